"""Which channels make the colour features worse than grey on 7-Scenes? (issue 12)

Usage::

    python benchmarks/colour_channel_study.py --out DIR [--variants lab-l,grey-ab] [--seeds 0-2] [--jobs 2]
        [--sequences 7scenes] [--data ../shared/data]

Registers channel subsets of ``lab`` and ``rgb`` as features of their own, calibrates each exactly as the packaged
features are calibrated (default scale: the semi-dense pixel count of grey on the 20 sample frames of
``data/7scenes-redkitchen-0000-0299``; N_E and κ: :func:`dmtrack.features.scale.measure_channel_statistics` on the
same frames), then runs them through ``channel_cost_ablation.py`` with the default rule (``balanced``):

* ``lab-l``: L* alone (2.55·L*), one channel — is the L* curve itself worse than grey?
* ``grey-ab``: grey (OpenCV's RGB→grey, the ``gray`` feature's input) with a*+128 and b*+128 — do the chroma
  channels hurt when the luminance channel is grey's own?
* ``lab-ab``: a*+128 and b*+128 alone (chroma only; may not track);
* ``rgb-g``: the green channel alone;
* ``lab-cs2``, ``grey-ab-cs2``: ``lab`` and ``grey-ab`` with a* and b* Gaussian-blurred (σ = 2 px);
* ``lab-chroma2``, ``rgb-chroma2``: the package's ``lab`` and ``rgb`` with ``chroma_sigma=2``.

The calibration is printed and written to ``DIR/calibration.json``; the rows and tables are the ablation script's.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from dmtrack.features.base import Feature, prepare_image, register  # noqa: E402
from dmtrack.features.colour import LabFeature, RgbFeature  # noqa: E402

SAMPLES = [REPO / "data" / "7scenes-redkitchen-0000-0299" / f"frame-{i:06d}.color.jpg" for i in range(0, 300, 15)]


def _lab(image: np.ndarray, chroma_sigma: float = 0.0) -> np.ndarray:
    """The package's lab at scale 1 (2.55·L*, a*+128, b*+128), plain or with its chroma low-pass."""
    return LabFeature(1.0, chroma_sigma=chroma_sigma).compute(image)


class _Subset(Feature):
    needs_colour = True
    pyramid = "downsample"

    def __init__(self, scale: float = 1.0) -> None:
        super().__init__(scale)

    def channels_of(self, image: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        out = np.ascontiguousarray(self.channels_of(image), dtype=np.float32)
        out *= np.float32(gain)
        return out


class LabL(_Subset):
    name, channels, description = "lab-l", 1, "2.55·L* alone"

    def channels_of(self, image: np.ndarray) -> np.ndarray:
        return _lab(image)[:, :, :1]


class LabAB(_Subset):
    name, channels, description = "lab-ab", 2, "a*+128, b*+128 alone"

    def channels_of(self, image: np.ndarray) -> np.ndarray:
        return _lab(image)[:, :, 1:]


class GreyAB(_Subset):
    name, channels, description = "grey-ab", 3, "grey (the gray feature's input), a*+128, b*+128"

    def channels_of(self, image: np.ndarray) -> np.ndarray:
        lab = _lab(image)
        lab[:, :, 0] = prepare_image(image, colour=False)
        return lab


class RgbG(_Subset):
    name, channels, description = "rgb-g", 1, "the green channel alone"

    def channels_of(self, image: np.ndarray) -> np.ndarray:
        return image[:, :, 1:2]


class LabCS2(_Subset):
    name, channels, description = "lab-cs2", 3, "lab with a*, b* Gaussian-blurred (sigma 2 px)"

    def channels_of(self, image: np.ndarray) -> np.ndarray:
        return _lab(image, 2.0)


class GreyABCS2(_Subset):
    name, channels, description = "grey-ab-cs2", 3, "grey-ab with a*, b* Gaussian-blurred (sigma 2 px)"

    def channels_of(self, image: np.ndarray) -> np.ndarray:
        lab = _lab(image, 2.0)
        lab[:, :, 0] = prepare_image(image, colour=False)
        return lab


def _packaged(cls: type, name: str, **options: float) -> type:
    """The package's feature ``cls`` with ``options``, under its own name (so that the registry's N_E and κ for
    ``name`` are used, not those measured for the default options)."""
    return type(name.replace("-", "_"), (cls,), {"name": name, "__init__": lambda self, scale=1.0: cls.__init__(
        self, scale, **options)})  # fmt: skip


VARIANTS = {c.name: c for c in (LabL, LabAB, GreyAB, RgbG, LabCS2, GreyABCS2)}
VARIANTS["lab-chroma2"] = _packaged(LabFeature, "lab-chroma2", chroma_sigma=2.0)
VARIANTS["rgb-chroma2"] = _packaged(RgbFeature, "rgb-chroma2", chroma_sigma=2.0)


def calibrate(names: list[str]) -> dict[str, dict]:
    from dmtrack.features.scale import calibrate_scale_detailed, measure_channel_statistics
    from dmtrack.io.images import read_image

    images = [read_image(p) for p in SAMPLES]
    table = {}
    for name in names:
        cls = VARIANTS[name]
        cal = calibrate_scale_detailed(cls(1.0), images, 5.0)
        st = measure_channel_statistics(cls(cal.scale), images)
        table[name] = {"scale": round(cal.scale, 4), "target_count": round(cal.target_count, 1),
                       "achieved_count": round(cal.achieved_count, 1),
                       "energy_channels": round(st.energy_channels, 3), "info_channels": round(st.info_channels, 3),
                       "noise_channels": round(st.noise_channels, 3)}  # fmt: skip
        print(name, table[name], flush=True)
    return table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--variants", default="lab-l,grey-ab")
    ap.add_argument("--seeds", default="0-2")
    ap.add_argument("--jobs", default="2")
    ap.add_argument("--sequences", default="7scenes")
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"))
    a = ap.parse_args(argv)
    names = a.variants.split(",")
    unknown = sorted(set(names) - set(VARIANTS))
    if unknown:
        ap.error(f"unknown variants {unknown}; known: {sorted(VARIANTS)}")
    a.out.mkdir(parents=True, exist_ok=True)
    cal_file = a.out / "calibration.json"
    table = json.loads(cal_file.read_text()) if cal_file.exists() else {}
    missing = [n for n in names if n not in table]
    if missing:
        table.update(calibrate(missing))
        cal_file.write_text(json.dumps(table, indent=1) + "\n")
    for name in names:
        c = table[name]
        register(name, VARIANTS[name], channels=VARIANTS[name].channels, needs_colour=True, scale=c["scale"],
                 energy_channels=c["energy_channels"], info_channels=c["info_channels"],
                 description=VARIANTS[name].description, replace=True)  # fmt: skip
    import channel_cost_ablation

    return channel_cost_ablation.run_default_rule(a.out, names, a.sequences, a.seeds, a.jobs, a.data)


if __name__ == "__main__":
    sys.exit(main())
