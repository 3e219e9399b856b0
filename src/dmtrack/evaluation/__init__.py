"""dmtrack.evaluation: Umeyama alignment, trajectory error metrics, and the bench's records, tables and report.

Alignment and metrics are pure numpy; see :mod:`dmtrack.evaluation.metrics` for the definitions (the paper's §3.1
RPE). Timestamp association lives in :mod:`dmtrack.io.association` (the readers use it too).
"""

from dmtrack.evaluation.alignment import (
    ALIGN_MODES,
    AlignMode,
    align_trajectory,
    apply_sim3,
    sim3_matrix,
    umeyama,
)
from dmtrack.evaluation.metrics import (
    UNDEFINED_ANGLE_DEG,
    AteResult,
    ErrorStats,
    RotationGain,
    RpeResult,
    RpeStats,
    ate,
    evaluate,
    rotation_gain,
    rotation_gain_text,
    rpe,
    rpe_pairs,
    rpe_paper,
)

__all__ = [
    "ALIGN_MODES",
    "AlignMode",
    "AteResult",
    "ErrorStats",
    "RotationGain",
    "RpeResult",
    "RpeStats",
    "UNDEFINED_ANGLE_DEG",
    "align_trajectory",
    "apply_sim3",
    "ate",
    "evaluate",
    "rotation_gain",
    "rotation_gain_text",
    "rpe",
    "rpe_pairs",
    "rpe_paper",
    "sim3_matrix",
    "umeyama",
]
