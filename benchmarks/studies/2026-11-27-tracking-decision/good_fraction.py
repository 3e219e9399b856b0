"""Good fraction per tracked frame under candidate constants K of the good/bad test (good ⇔ e < K + ¼G).

Reads the ``.npz`` files of ``benchmarks/good_test_residuals.py`` (named ``*_FEATURE.npz``) and prints, per candidate,
the minimum, 5th percentile and median over the tracking calls of the fraction of in-image points that pass, and the
last three calls. A frame is "not good" (a loss after 5 keyframes) when that fraction is ≤ 0.5. N_V: the
unrelated-pair energy ratios of ``unrelated_pair_energy.txt``.

    python benchmarks/studies/2026-11-27-tracking-decision/good_fraction.py FILE.npz ...
"""

from __future__ import annotations

import sys

import numpy as np

N_V = {"gray": 1.0, "rgb": 3.012, "lab": 5.470, "bitplanes": 0.073, "dsift": 7.162, "tracknet": 0.766, "tfeat": 19.334}


def candidates(feature: str, n_e: float, n_s: float) -> dict[str, float]:
    n_v = N_V[feature]
    return {
        "N_E*1600 (the flags)": n_e * 1600,
        "N_E*1600+(N_s-N_E)*16 (the verdict)": n_e * 1600 + (n_s - n_e) * 16,
        "N_V*1600": n_v * 1600,
        "N_V*1600+(N_s-N_V)*4": n_v * 1600 + (n_s - n_v) * 4,
        "N_V*1600+(N_s-N_V)*16": n_v * 1600 + (n_s - n_v) * 16,
    }


def main() -> None:
    for path in sys.argv[1:]:
        feature = path.rsplit("_", 1)[-1].removesuffix(".npz")
        z = np.load(path)
        e, g, call = z["e"], z["g"], z["call"]
        n = len(z["n"])
        print(f"{path}: {n} tracking calls")
        for name, k in candidates(feature, float(z["energy_channels"]), float(z["noise_energy_channels"])).items():
            fr = np.array([np.mean(e[call == i] < k + 0.25 * g[call == i]) for i in range(n)])
            print(f"  {name:38s} K={k:9.1f}  good fraction min {fr.min():.3f}  p5 {np.percentile(fr, 5):.3f}  "
                  f"median {np.median(fr):.3f}  last 3 {np.round(fr[-3:], 3).tolist()}")


if __name__ == "__main__":
    main()
