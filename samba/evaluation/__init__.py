"""The accuracy protocol of EVALUATION.md: simulated capture of test takes, reconstruction
by every method, errors per joint and per take in cm at a 45 cm tibia, text reports, the
JSON document and plots (`samba eval`).
"""

from samba.evaluation.experiment import (
    Evaluation,
    document,
    evaluate,
    report_text,
    sweep_points,
    write_plots,
)
from samba.evaluation.protocol import TakeErrors, capture_take, run_method, summarize

__all__ = [
    "Evaluation",
    "TakeErrors",
    "capture_take",
    "document",
    "evaluate",
    "report_text",
    "run_method",
    "summarize",
    "sweep_points",
    "write_plots",
]
