"""The PNG plots of `samba eval`, drawn with matplotlib's Agg backend (no display).

Error over time per take, error per joint, and the paper's sweeps: error and time per
frame against K (its Fig. 8) and against N for several K (its Fig. 9). Errors are in cm
at the 45 cm reference tibia, times in ms (live path, median per frame).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from samba.body import JOINT_NAMES
from samba.evaluation.protocol import TakeErrors
from samba.evaluation.report import Summary, SweepPoint

FPS = 30.0
"""Frame rate of the evaluated takes (the database rate), frames per second."""


def _figure(width: float, height: float, panels: int = 1) -> tuple[Figure, list]:
    """A figure with an Agg canvas and `panels` axes side by side."""
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig, [fig.add_subplot(1, panels, i + 1) for i in range(panels)]


def _file_name(text: str) -> str:
    """text with everything but letters, digits, '.', '-' and '_' replaced by '_'."""
    return re.sub(r"[^\w.-]", "_", text)


def error_over_time(results: Mapping[str, Sequence[TakeErrors]], directory: Path) -> list[Path]:
    """One PNG per test take, `error_time_<take>.png`: mean joint error of every frame
    (cm) against time (s), one line per run. Returns the files written."""
    written = []
    labels = list(results)
    for i, first in enumerate(results[labels[0]]):
        fig, (ax,) = _figure(9, 4)
        for label in labels:
            take = results[label][i]
            error = take.errors.mean(axis=1) * take.scale * 100.0
            ax.plot(np.arange(len(error)) / FPS, error, label=label, linewidth=1)
        ax.set(xlabel="time (s)", ylabel="mean joint error (cm)", title=first.name)
        ax.set_ylim(bottom=0)
        ax.legend()
        path = directory / f"error_time_{_file_name(first.name)}.png"
        fig.savefig(path, dpi=100)
        written.append(path)
    return written


def error_per_joint(summaries: Mapping[str, Summary], path: Path) -> Path:
    """Grouped bars: mean error (cm) of each of the 13 joints, one bar per run."""
    fig, (ax,) = _figure(11, 4.5)
    x = np.arange(len(JOINT_NAMES))
    width = 0.8 / len(summaries)
    for i, (label, s) in enumerate(summaries.items()):
        per_joint = s["per_joint_cm"]
        values = [per_joint[name] for name in JOINT_NAMES]
        ax.bar(x + (i - (len(summaries) - 1) / 2) * width, values, width, label=label)
    ax.set_xticks(x, JOINT_NAMES, rotation=45, ha="right")
    ax.set(ylabel="mean error (cm)", title="error per joint")
    ax.legend()
    fig.savefig(path, dpi=100)
    return path


def k_sweep(points: Sequence[SweepPoint], summaries: Mapping[str, Summary], path: Path) -> Path:
    """The paper's Fig. 8: error (cm) and time per frame (ms) against K, two panels."""
    fig, (err, ms) = _figure(10, 4, panels=2)
    ks = [k for k, _, _ in points]
    n = points[0][1]
    err.plot(ks, [summaries[lab]["mpjpe_cm"] for *_, lab in points], "o-", label="all joints")
    err.plot(ks, [summaries[lab]["unobserved_cm"] for *_, lab in points], "s--", label="unobserved")
    err.set(xlabel="K (neighbours)", ylabel="mean error (cm)", title=f"error against K (N = {n})")
    err.set_ylim(bottom=0)
    err.legend()
    ms.plot(ks, [summaries[lab]["frame_ms_p50"] for *_, lab in points], "o-")
    ms.set(xlabel="K (neighbours)", ylabel="time per frame, median (ms)", title="time against K")
    ms.set_ylim(bottom=0)
    fig.savefig(path, dpi=100)
    return path


def n_sweep(points: Sequence[SweepPoint], summaries: Mapping[str, Summary], path: Path) -> Path:
    """The paper's Fig. 9: error (cm) and time per frame (ms) against N, a line per K."""
    fig, (err, ms) = _figure(10, 4, panels=2)
    for k in sorted({k for k, _, _ in points}):
        line = sorted((n, lab) for kk, n, lab in points if kk == k)
        ns = [n for n, _ in line]
        err.plot(ns, [summaries[lab]["mpjpe_cm"] for _, lab in line], "o-", label=f"K = {k}")
        ms.plot(ns, [summaries[lab]["frame_ms_p50"] for _, lab in line], "o-", label=f"K = {k}")
    err.set(
        xlabel="N (pseudo-poses per neighbour)", ylabel="mean error (cm)", title="error against N"
    )
    ms.set(
        xlabel="N (pseudo-poses per neighbour)",
        ylabel="time per frame, median (ms)",
        title="time against N",
    )
    for ax in (err, ms):
        ax.set_ylim(bottom=0)
        ax.legend()
    fig.savefig(path, dpi=100)
    return path
