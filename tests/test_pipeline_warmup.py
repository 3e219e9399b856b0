"""Compilation apart from the run: :func:`dmtrack.pipeline.warm_up` calls every kernel a run calls, a run reports its
warm-up as ``compile_s`` and its ``fps`` starts after it, results do not depend on it, and ``dmtrack warmup``.

The kernels a process has compiled or loaded cannot be unloaded, so the checks that need a fresh process run one.
"""

from __future__ import annotations

import importlib.util
import json
import re
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from dmtrack.cli import main
from dmtrack.features import get_feature
from dmtrack.pipeline import run_to_directory

# In a fresh process: warm up grey, then run 40 frames of the sample (two keyframe changes, the threaded tracker on
# two cores) and list the kernels that got a new compiled version meanwhile; then a run of another feature that
# warms itself up, and the same run without warm-up.
FRESH = r"""
import json, sys, time
from numba.core.dispatcher import Dispatcher
from dmtrack.pipeline import run_to_directory, track, warm_up

def overloads():
    found = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("dmtrack.") and module is not None:
            for attr, value in vars(module).items():
                if isinstance(value, Dispatcher):
                    found[f"{name}.{attr}"] = len(value.overloads)
    return found

sample, out = sys.argv[1], sys.argv[2]
warm_s = warm_up("gray")
before = overloads()
run = track(sample, "gray", max_frames=40)
after = overloads()
t0 = time.perf_counter()
affine = run_to_directory(sample, out + "/warm", "gray-affine", max_frames=12, depth_images=False, pointcloud=False)
elapsed = time.perf_counter() - t0
cold = run_to_directory(sample, out + "/plain", "gray-affine", max_frames=12, depth_images=False, pointcloud=False,
                        warmup=False)
print(json.dumps({
    "warm_s": warm_s, "again": warm_up("gray"), "run_compile_s": run.metrics["compile_s"],
    "keyframes": run.metrics["keyframes"], "kernels_used": sum(1 for n in before.values() if n),
    "new": {k: [before.get(k, 0), n] for k, n in after.items() if n != before.get(k, 0)},
    "affine": affine.metrics, "affine_elapsed": elapsed, "plain": cold.metrics,
}))
"""


@pytest.fixture(scope="module")
def fresh(sample_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("fresh")
    done = subprocess.run([sys.executable, "-c", FRESH, str(sample_dir), str(out)], capture_output=True, text=True,
                          timeout=900)  # a fresh checkout compiles the kernels first
    assert done.returncode == 0, done.stderr
    return {**json.loads(done.stdout.splitlines()[-1]), "out": out}


def test_a_run_after_the_warm_up_compiles_nothing(fresh: dict[str, Any]) -> None:
    assert fresh["warm_s"] > 0 and fresh["again"] == 0.0  # once per process
    assert fresh["kernels_used"] >= 15 and fresh["keyframes"] >= 2
    assert fresh["new"] == {}, "kernels compiled or loaded during the run, after the warm-up"
    assert fresh["run_compile_s"] == 0.0  # the run found nothing left to warm up


def test_compile_s_is_reported_apart_from_fps(fresh: dict[str, Any]) -> None:
    m = fresh["affine"]
    assert m["compile_s"] > 0  # another configuration (affine brightness): warmed up by the run itself
    assert m["fps"] == pytest.approx(m["processed_frames"] / m["wall_s"])
    assert m["wall_s"] + m["compile_s"] <= fresh["affine_elapsed"]  # the loop's time does not include it
    assert fresh["plain"]["compile_s"] == 0.0  # warmup=False


def test_warm_up_does_not_change_the_results(fresh: dict[str, Any]) -> None:
    out = fresh["out"]
    for name in ("trajectory.txt", "keyframes.txt"):
        assert (out / "warm" / name).read_bytes() == (out / "plain" / name).read_bytes()
    assert json.loads((out / "warm" / "metrics.json").read_text())["compile_s"] == fresh["affine"]["compile_s"]


class _SignalDuringWarmUp:
    """Grey that sends this process SIGINT (Ctrl-C) when it sees the first warm-up frame (256×192)."""

    name = "gray-ctrl-c"  # not warmed up by another test of this process

    def __init__(self) -> None:
        self._gray = get_feature("gray")
        self._sent = False

    def __getattr__(self, key: str) -> Any:
        return getattr(self._gray, key)

    def compute(self, image: Any) -> Any:
        if image.shape[:2] == (192, 256) and not self._sent:  # once: a second Ctrl-C would stop at once
            self._sent = True
            signal.raise_signal(signal.SIGINT)
        return self._gray.compute(image)


def test_ctrl_c_during_the_warm_up_stops_before_the_first_frame(tmp_path: Path, sample_dir: Path) -> None:
    with pytest.raises(KeyboardInterrupt):
        run_to_directory(sample_dir, tmp_path, _SignalDuringWarmUp(), max_frames=10, depth_images=False)
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert (m["interrupted"], m["processed_frames"], m["tracked_frames"]) == ("SIGINT", 0, 0)
    assert m["compile_s"] > 0
    assert (tmp_path / "trajectory.txt").read_text().count("\n") == 1  # the header only


def test_warmup_command(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["warmup", "--feature", "gray", "--feature", "rgb"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines[:2]] == ["gray", "rgb"]
    for line in lines[:2]:
        assert re.fullmatch(r"\S+ +\d+\.\d s  \(\d+ kernels compiled, \d+ loaded from the cache\)", line), line
    assert lines[2].startswith("numba's cache: ") and Path(lines[2].split(": ", 1)[1]).is_dir()
    assert re.fullmatch(r"Python bytecode: \d+ of dmtrack's modules compiled into __pycache__", lines[3]), lines[3]
    # every module of the package now has a fresh cache: the next import compiles nothing
    import dmtrack
    from dmtrack.io.machine import _bytecode_fresh

    sources = sorted(Path(dmtrack.__file__).parent.rglob("*.py"))
    assert sources and all(_bytecode_fresh(p, Path(importlib.util.cache_from_source(str(p)))) for p in sources)
    assert main(["warmup", "--feature", "no-such-feature"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no-such-feature" in err[0]
