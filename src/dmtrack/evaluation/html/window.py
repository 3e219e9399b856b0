"""The run report's section on the sliding window (``metrics.json``'s ``window``: docs/window.md)."""

from __future__ import annotations

from typing import Any

from dmtrack.evaluation.html.page import Page, key_value_table
from dmtrack.evaluation.tables import fmt_value


def window_section(page: Page, m: dict[str, Any]) -> None:
    """What the window did: optimisations, their time, the cost they removed, and the intrinsics it estimated."""
    w = m.get("window")
    if not isinstance(w, dict):
        return
    page.heading(2, "Sliding window", toc=True)
    ratio = w.get("median_cost_ratio")
    items = [
        ("Optimisations (one per keyframe change)", fmt_value(w.get("optimisations"))),
        ("Keyframes that left the window during the run", f"{fmt_value(w.get('left'))} ({w.get('leave', 'fixed')})"),
        ("Time per optimisation (ms)", fmt_value(w.get("ms_per_optimisation"), 1)),
        ("Median cost after / before", fmt_value(ratio, 3)),
    ]
    K, S = w.get("intrinsics"), w.get("intrinsics_sigma") or {}
    if isinstance(K, dict):
        for name in ("fx", "fy", "cx", "cy"):
            sig = S.get(name)
            items.append((f"Estimated {name} (px)", fmt_value(K.get(name), 2)
                          + (f" ± {fmt_value(sig, 2)}" if sig is not None else " (held)")))  # fmt: skip
    page.add(key_value_table(items))
    page.text("The newest keyframes' poses and their points' inverse depths are optimised jointly at each keyframe "
              "change (photometric bundle adjustment on the feature's channels); trajectory.txt places every frame by "
              "its keyframe's final pose. Estimated intrinsics: the inverse-variance mean over the optimisations, its "
              "± from the windows taken as independent (optimistic).", "caption")  # fmt: skip
