#!/usr/bin/env python3
"""Insert dmtrack's read-only trace hooks into a checkout of LSD-SLAM's lsd_slam_core (build.sh calls this).

Each insertion is one guarded call ``if(lsd_oracle_hook) lsd_oracle_hook(EVENT, obj, frame);`` placed after a
line of upstream code that identifies the spot; the script fails if a spot is not found exactly once, so an
unexpected upstream revision is noticed instead of silently mis-instrumented. No algorithmic change.
"""

import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

# (file, anchor line (stripped), event, object expression, frame expression, before/after)
HOOKS = [
    ("DepthEstimation/DepthMap.cpp", "observeDepth();", "LSD_ORACLE_BEFORE_UPDATE", "this",
     "newest_referenceFrame", "before"),
    ("DepthEstimation/DepthMap.cpp", "activeKeyFrame->numMappedOnThisTotal++;", "LSD_ORACLE_AFTER_UPDATE", "this",
     "newest_referenceFrame", "after"),
    ("DepthEstimation/DepthMap.cpp", "propagateDepth(new_keyframe);", "LSD_ORACLE_BEFORE_CREATE", "this",
     "new_keyframe", "before"),
    ("DepthEstimation/DepthMap.cpp", "activeKeyFrame->pose->invalidateCache();", "LSD_ORACLE_AFTER_CREATE",
     "this", "activeKeyFrame", "after"),
    ("Tracking/SE3Tracker.cpp", "frame->pose->trackingParent = reference->keyframe->pose;",
     "LSD_ORACLE_AFTER_TRACK", "this", "frame", "after"),
]


def main(core: Path) -> None:
    src = core / "src"
    for name in ("lsd_oracle_hooks.h", "lsd_oracle_hooks.cpp"):
        shutil.copy(HERE / name, src / name)
    for rel in sorted({h[0] for h in HOOKS}):
        path = src / rel
        lines = path.read_text().split("\n")
        for f, anchor, event, obj, frame, where in HOOKS:
            if f != rel:
                continue
            hits = [i for i, ln in enumerate(lines) if ln.strip() == anchor]
            if len(hits) != 1:
                sys.exit(f"add_hooks: {rel}: anchor {anchor!r} found {len(hits)} times (expected 1)")
            i = hits[0]
            indent = lines[i][: len(lines[i]) - len(lines[i].lstrip())]
            call = f"{indent}if(lsd_oracle_hook) lsd_oracle_hook({event}, {obj}, {frame});"
            lines.insert(i if where == "before" else i + 1, call)
        lines.insert(0, '#include "lsd_oracle_hooks.h"')
        path.write_text("\n".join(lines))
        print(f"add_hooks: instrumented {rel}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
