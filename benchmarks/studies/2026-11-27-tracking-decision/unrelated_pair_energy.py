"""Residual energy of unrelated pixel pairs, per feature, relative to grey (N_V).

For each of the 20 sample frames of ``default_scales.json`` (every 15th of data/7scenes-redkitchen-0000-0299), the
feature at its default scale, its semi-dense pixels (channel-mean gradient after the 3×3 max filter > 5, 8-px border
dropped), 20000 random pairs of them (seed 0): the mean of Σ_c (F_c(p) − F_c(q))². N_V is that over grey's. It is the
residual an occluded or wrongly aligned point has, which the tracker's good/bad test is meant to reject. Run from the
repository root::

    python benchmarks/studies/2026-11-27-tracking-decision/unrelated_pair_energy.py rgb lab bitplanes dsift tracknet
"""

from __future__ import annotations

import glob
import sys

import numpy as np

from dmtrack.features import get_feature
from dmtrack.features.scale import channel_mean_gradient
from dmtrack.io.images import read_image

PATHS = sorted(glob.glob("data/7scenes-redkitchen-0000-0299/frame-*.color.jpg"))[::15][:20]


def pair_energy(name: str, images: list[np.ndarray], rng: np.random.Generator) -> float:
    f = get_feature(name)
    tot, n = 0.0, 0
    for im in images:
        feat = f.compute(im)
        m = channel_mean_gradient(feat) > 5.0
        m[:8] = m[-8:] = False
        m[:, :8] = m[:, -8:] = False
        ys, xs = np.nonzero(m)
        i = rng.integers(0, len(ys), 20000)
        j = rng.integers(0, len(ys), 20000)
        d = feat[ys[i], xs[i]].astype(np.float64) - feat[ys[j], xs[j]]
        tot += float((d**2).sum())
        n += len(i)
    return tot / n


def main() -> None:
    images = [read_image(p) for p in PATHS]
    rng = np.random.default_rng(0)
    grey = pair_energy("gray", images, rng)
    print(f"gray {grey:.1f}")
    for name in sys.argv[1:]:
        e = pair_energy(name, images, rng)
        print(f"{name} {e:.1f} N_V {e / grey:.3f}", flush=True)


if __name__ == "__main__":
    main()
