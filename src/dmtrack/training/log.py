"""The training's log (:func:`dmtrack.training.train.train`): ``train_log.csv``, one row per step, and
``training_curve.png``."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.io.atomic import write_bytes, write_text

#: The columns of ``train_log.csv``.
LOG_COLUMNS = ("step", "seconds", "lr", "loss", "scale_term", "default_scale", "init_px", "final_px", "grad_norm",
               "skipped")  # fmt: skip


def write_log(out: Path, rows: list[dict[str, Any]]) -> None:
    buf = io.StringIO()
    wr = csv.DictWriter(buf, fieldnames=LOG_COLUMNS, lineterminator="\n")
    wr.writeheader()
    for r in rows:
        wr.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    write_text(out / "train_log.csv", buf.getvalue())


def plot_curve(out: Path, rows: list[dict[str, Any]]) -> Path | None:
    """``training_curve.png``: loss and final reprojection error per step (and a running mean); None without
    matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - matplotlib is a dependency
        return None
    if not rows:
        return None
    steps = np.array([r["step"] for r in rows])
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, key, label in ((axes[0], "loss", "loss"), (axes[1], "final_px", "final reprojection error (px)")):
        v = np.array([r[key] for r in rows], float)
        ax.plot(steps, v, lw=0.5, alpha=0.4, color="tab:blue")
        win = max(1, len(v) // 20)
        ok = np.isfinite(v)
        if ok.sum() >= win:
            kern = np.ones(win) / win
            sm = np.convolve(np.where(ok, v, np.nanmean(v)), kern, mode="valid")
            ax.plot(steps[win - 1 :], sm, color="tab:blue", label=f"mean of {win}")
            ax.legend()
        if key == "final_px":
            init = np.array([r["init_px"] for r in rows], float)
            ax.axhline(float(np.nanmean(init)), color="grey", ls="--", lw=1, label="initial (mean)")
            ax.set_yscale("log")
        ax.set_xlabel("step")
        ax.set_ylabel(label)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    path = out / "training_curve.png"
    write_bytes(path, buf.getvalue())
    return path
