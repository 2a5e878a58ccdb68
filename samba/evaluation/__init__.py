"""The accuracy protocol of EVALUATION.md: simulated capture of test takes, reconstruction
by every method, errors per joint and per take in cm at a 45 cm tibia, text reports, the
JSON document and plots (`samba eval`); real marker takes scored against reference joint
centres, raw, with the subject's skin offsets calibrated, and with synthetic markers.
"""

from samba.evaluation.experiment import (
    Evaluation,
    document,
    evaluate,
    evaluate_take,
    report_text,
    sweep_points,
    write_plots,
)
from samba.evaluation.protocol import (
    EVALUATION_FPS,
    TakeErrors,
    capture_take,
    run_method,
    summarize,
)
from samba.evaluation.real_markers import (
    MarkerEvaluation,
    MarkerTest,
    evaluate_markers,
    marker_document,
    marker_report,
    offset_removed_errors,
)

__all__ = [
    "EVALUATION_FPS",
    "Evaluation",
    "MarkerEvaluation",
    "MarkerTest",
    "TakeErrors",
    "capture_take",
    "document",
    "evaluate",
    "evaluate_markers",
    "evaluate_take",
    "marker_document",
    "marker_report",
    "offset_removed_errors",
    "report_text",
    "run_method",
    "summarize",
    "sweep_points",
    "write_plots",
]
