"""Training loop (dmtrack.training.train) and its CLI parser: deterministic, files written, bad options refused."""

from __future__ import annotations

import argparse
import csv
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from dmtrack.errors import InputError  # noqa: E402
from dmtrack.training.cli import add_train_parser  # noqa: E402
from dmtrack.training.train import TrainOptions, train  # noqa: E402

SMALL = dict(steps=3, batch=1, val_pairs=0, n_sequences=1, n_frames=20, crop=(160, 128), max_points=800,
             checkpoint_every=2)  # fmt: skip


def test_same_seed_gives_byte_identical_weights(tmp_path) -> None:
    a = train(tmp_path / "a", TrainOptions(seed=5, **SMALL))
    b = train(tmp_path / "b", TrainOptions(seed=5, **SMALL))
    c = train(tmp_path / "c", TrainOptions(seed=6, **SMALL))
    assert a.steps == b.steps == c.steps == 3
    wa, wb, wc = ((tmp_path / d / "tracknet.npz").read_bytes() for d in "abc")
    assert wa == wb
    assert wa != wc  # the seed matters (so the equality above is not vacuous)
    with np.load(tmp_path / "a" / "tracknet.npz") as z:
        meta = json.loads(str(z["meta"]))
    assert meta["steps"] == 3 and meta["seed"] == 5 and meta["preliminary"] is True
    # the log: one row per step, finite losses, and the training actually moved the weights
    rows = list(csv.DictReader((tmp_path / "a" / "train_log.csv").open()))
    assert [int(r["step"]) for r in rows] == [1, 2, 3]
    assert all(np.isfinite(float(r["loss"])) for r in rows)
    summary = json.loads((tmp_path / "a" / "train_log.json").read_text())
    assert summary["steps"] == 3 and summary["options"]["seed"] == 5
    assert (tmp_path / "a" / "training_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "a" / "checkpoint.pt").is_file()
    ckpt = torch.load(tmp_path / "a" / "checkpoint.pt", weights_only=True)
    assert ckpt["step"] == 3
    torch.manual_seed(5)
    from dmtrack.training.model import TrackNet

    init = TrackNet(8, 8, (5, 3)).state_dict()
    assert any(not torch.equal(init[k], ckpt["model"][k]) for k in init)
    assert not list(tmp_path.glob("*/.*.tmp"))  # atomic writes left nothing behind


def test_bad_options_are_input_errors(tmp_path) -> None:
    for bad in (dict(data="7scenes"), dict(data="kitti"), dict(channels=0), dict(minutes=0.0), dict(crop=(100, 100))):
        with pytest.raises(InputError):
            train(tmp_path / "x", TrainOptions(**{**SMALL, **bad}))
    assert not (tmp_path / "x").exists()


def test_cli_parser() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    add_train_parser(sub)
    args = parser.parse_args(["train-feature", "--out", "o", "--minutes", "1.5", "--channels", "4", "--seed", "2"])
    got = (args.out, args.minutes, args.channels, args.seed, args.data, args.threads)
    assert got == ("o", 1.5, 4, 2, "synthetic", 1)
    assert args.func.__name__ == "cmd_train_feature"
    args = parser.parse_args(["train-feature", "--out", "o", "--data", "7scenes"])
    with pytest.raises(InputError, match="not implemented yet"):
        args.func(args)
    for bad in (["--minutes", "0"], ["--channels", "0"], ["--data", "kitti"]):
        with pytest.raises(SystemExit):
            parser.parse_args(["train-feature", "--out", "o", *bad])
