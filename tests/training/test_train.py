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
    assert meta["steps"] == 3 and meta["seed"] == 5
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
    bad_options = (dict(data="7scenes"), dict(data="kitti"), dict(channels=0), dict(minutes=0.0), dict(crop=(100, 100)),
                   dict(lr_schedule="step"), dict(lr_schedule="cosine", steps=None), dict(lr_final=0.0))
    for bad in bad_options:
        with pytest.raises(InputError):
            train(tmp_path / "x", TrainOptions(**{**SMALL, **bad}))
    assert not (tmp_path / "x").exists()


def test_cosine_schedule_runs_from_lr_to_its_final_fraction(tmp_path) -> None:
    from dmtrack.training.train import learning_rate

    opts = TrainOptions(steps=100, lr=1e-3, lr_schedule="cosine", lr_final=0.05)
    rates = [learning_rate(opts, s) for s in range(101)]
    assert rates[0] == pytest.approx(1e-3) and rates[50] == pytest.approx(0.525e-3)
    assert rates[100] == pytest.approx(5e-5)
    assert all(a > b for a, b in zip(rates[:-1], rates[1:], strict=True))
    assert learning_rate(TrainOptions(steps=100), 70) == 1e-3  # constant is the default
    cosine = TrainOptions(seed=5, lr_schedule="cosine", **SMALL)
    train(tmp_path / "c", cosine)
    rows = list(csv.DictReader((tmp_path / "c" / "train_log.csv").open()))
    assert [float(r["lr"]) for r in rows] == pytest.approx([learning_rate(cosine, s) for s in range(3)])
    assert float(rows[0]["lr"]) > float(rows[2]["lr"])


def test_cli_parser() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    add_train_parser(sub)
    args = parser.parse_args(["train-feature", "--out", "o", "--minutes", "1.5", "--channels", "4", "--seed", "2"])
    assert args.lr_schedule == "constant"
    got = (args.out, args.minutes, args.channels, args.seed, args.data, args.threads)
    assert got == ("o", 1.5, 4, 2, "synthetic", 1)
    assert args.func.__name__ == "cmd_train_feature"
    args = parser.parse_args(["train-feature", "--out", "o", "--data", "7scenes"])
    with pytest.raises(InputError, match="needs --data-path"):
        args.func(args)
    for bad in (["--minutes", "0"], ["--channels", "0"], ["--data", "kitti"]):
        with pytest.raises(SystemExit):
            parser.parse_args(["train-feature", "--out", "o", *bad])


def test_device_option(tmp_path) -> None:
    from dmtrack.features.device import cuda_problem

    with pytest.raises(InputError, match="device must be"):
        train(tmp_path / "x", TrainOptions(device="gpu", **SMALL))
    problem = cuda_problem()
    if problem is not None:  # a machine without a usable GPU: one line naming what is missing, nothing written
        with pytest.raises(InputError) as exc:
            train(tmp_path / "x", TrainOptions(device="cuda", **SMALL))
        assert str(exc.value) == f"device=cuda: {problem}"
    assert not (tmp_path / "x").exists()
    parser = argparse.ArgumentParser()
    add_train_parser(parser.add_subparsers(dest="command"))
    assert parser.parse_args(["train-feature", "--out", "o"]).device == "cpu"
    assert parser.parse_args(["train-feature", "--out", "o", "--device", "cuda:1"]).device == "cuda:1"
