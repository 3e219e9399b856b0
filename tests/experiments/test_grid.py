"""The grid of a bench: sequence names and run specs (:func:`~dmtrack.experiments.grid.plan_grid`), the
sequences file."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from dmtrack.errors import InputError
from dmtrack.experiments.grid import SequenceSpec, load_sequences_file, plan_grid

SYN = "synthetic:n_frames=25,width=320,height=240,seed=1,texel=0.02"
MISSING = "/nonexistent/dmtrack-test-sequence"


def test_plan_grid_names_and_specs(tmp_path: Path):
    tasks, seqs = plan_grid([SequenceSpec(MISSING, dataset="Mine"), MISSING, SYN], ["gray", "dsift"], tmp_path,
                            seed=3, overrides=["tracker.huber_d=2"])  # fmt: skip
    assert [s.name for s in seqs] == ["dmtrack-test-sequence", "dmtrack-test-sequence-2", "synthetic-seed1"]
    assert [s.dataset for s in seqs] == ["Mine", "unknown", "synthetic"]
    assert seqs[0].open_error and "no such file" in seqs[0].open_error
    assert [t.key for t in tasks][:2] == ["dmtrack-test-sequence/gray", "dmtrack-test-sequence/dsift"]
    spec = tasks[0].spec
    assert spec["seed"] == 3 and spec["overrides"] == ["tracker.huber_d=2"]
    assert spec["config"]["tracker"]["huber_d"] == 2.0 and spec["sequence"] == MISSING
    with pytest.raises(InputError):
        plan_grid([SYN], ["gray"], tmp_path, overrides=["tracker.no_such_key=1"])
    with pytest.raises(InputError, match="twice"):
        plan_grid([SYN], ["gray", "gray"], tmp_path)


def test_sequences_file(tmp_path: Path):
    (tmp_path / "data" / "seqA").mkdir(parents=True)
    f = tmp_path / "conf" / "seqs.yaml"
    f.parent.mkdir()
    f.write_text(
        textwrap.dedent("""
        defaults: {max_frames: 50}
        sequences:
          - ../data/seqA
          - path: ../data/seqA
            name: tsukuba-lamps
            format: image-folder
            intrinsics: [615, 615, 320, 240]
            r_l: 1/20
            max_frames: 150
            start: 5
            dataset: Tsukuba
            unit: cm
          - {path: "synthetic:n_frames=10", r_l: 0.25}
    """)
    )
    a, b, c = load_sequences_file(f)
    assert a == SequenceSpec(str((tmp_path / "data" / "seqA").resolve()), max_frames=50)
    assert b.name == "tsukuba-lamps" and b.intrinsics == "615,615,320,240" and b.r_l == pytest.approx(0.05)
    assert (b.max_frames, b.start, b.dataset, b.unit, b.format) == (150, 5, "Tsukuba", "cm", "image-folder")
    assert c.path == "synthetic:n_frames=10" and c.r_l == 0.25 and c.max_frames == 50
    f.write_text("sequences:\n  - {path: x, colour: true}\n")
    with pytest.raises(InputError, match="unknown key"):
        load_sequences_file(f)
    f.write_text("sequences:\n  - {path: x, r_l: 3}\n")
    with pytest.raises(InputError, match="r_l"):
        load_sequences_file(f)
    f.write_text("sequences: [a, b\n")
    with pytest.raises(InputError, match="invalid YAML"):
        load_sequences_file(f)
