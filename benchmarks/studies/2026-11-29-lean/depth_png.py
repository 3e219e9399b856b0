"""The depth pictures of a run, written as before (RGB through OpenCV) and as now (palette PNG): time per picture and
bytes, on the pictures a run wrote (their codes recovered through the colour table), best of 5 over all of them.

Usage: depth_png.py RUN_DIR [OUT.json]   (RUN_DIR: a `dmtrack run` folder with depth/*.png)
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from dmtrack.viz.depth import colour_table, palette_png


def _codes(path: Path, lookup: dict[bytes, int]) -> np.ndarray:
    rgb = cv2.imread(str(path), cv2.IMREAD_COLOR)[..., ::-1]
    flat = np.ascontiguousarray(rgb).reshape(-1, 3)
    colours, inverse = np.unique(flat, axis=0, return_inverse=True)
    index = np.array([lookup[c.tobytes()] for c in colours], np.uint8)
    return index[inverse.reshape(-1)].reshape(rgb.shape[:2])


def main(run: Path, out: Path | None) -> None:
    table = colour_table()
    lookup = {table[i].tobytes(): i for i in range(255, -1, -1)}  # the first index of a colour that repeats
    pictures = [_codes(p, lookup) for p in sorted((run / "depth").glob("*.png"))]
    lut = table.reshape(256, 1, 3)

    def before() -> int:
        n = 0
        for c in pictures:
            rgb = cv2.LUT(cv2.merge([c, c, c]), lut)
            n += len(cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))[1])
        return n

    def after() -> int:
        return sum(len(palette_png(c, table)) for c in pictures)

    result = {"pictures": len(pictures), "shape": list(pictures[0].shape)}
    for name, fn in (("before", before), ("after", after)):
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            size = fn()
            times.append(time.perf_counter() - t0)
        result[name] = {"ms_per_picture": 1e3 * min(times) / len(pictures), "bytes_per_picture": size / len(pictures)}
    print(json.dumps(result, indent=1))
    if out is not None:
        out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]) if len(sys.argv) > 2 else None)
