"""The text tables of `samba eval`: plain, aligned, one string each.

Every function takes summaries as `samba.evaluation.protocol.summarize` returns them, keyed by
run label (a method name, or a sweep point such as "samba K=20 N=5"). Errors are in cm
at the 45 cm reference tibia unless a column says m (unscaled meters); times in ms.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from samba.body import JOINT_NAMES, MARKER_JOINTS

Summary = Mapping[str, object]
SweepPoint = tuple[int, int, str]
"""(K, N, run label) of one point of a sweep."""


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """Columns padded to their widest cell: the first left-aligned, the others right."""
    cells = [list(header), *map(list, rows)]
    widths = [max(len(row[c]) for row in cells) for c in range(len(header))]
    lines = [
        "  ".join(
            cell.ljust(w) if c == 0 else cell.rjust(w)
            for c, (cell, w) in enumerate(zip(row, widths, strict=True))
        ).rstrip()
        for row in cells
    ]
    lines.insert(1, "-" * len(lines[0]))
    return "\n".join(lines)


def overall_table(summaries: Mapping[str, Summary]) -> str:
    """One row per run: scaled and unscaled errors (all, marker, unobserved joints),
    live time per frame (p50, p99), batch throughput and predicted frames."""
    header = [
        "method",
        "MPJPE cm",
        "marker cm",
        "unobs cm",
        "MPJPE m",
        "marker m",
        "unobs m",
        "p50 ms",
        "p99 ms",
        "batch f/s",
        "predicted",
    ]
    rows = [
        [
            label,
            f"{s['mpjpe_cm']:.2f}",
            f"{s['marker_cm']:.2f}",
            f"{s['unobserved_cm']:.2f}",
            f"{s['mpjpe_m']:.4f}",
            f"{s['marker_m']:.4f}",
            f"{s['unobserved_m']:.4f}",
            f"{s['frame_ms_p50']:.3f}",
            f"{s['frame_ms_p99']:.3f}",
            f"{s['batch_fps']:.0f}",
            f"{s['predicted_frames']}/{s['frames']}",
        ]
        for label, s in summaries.items()
    ]
    return table(header, rows)


def per_take_table(summaries: Mapping[str, Summary], frames: Mapping[str, int]) -> str:
    """Rows = test takes (with their frame counts), columns = runs: MPJPE in cm."""
    labels = list(summaries)
    rows = [
        [take, str(count), *(f"{summaries[m]['per_take_cm'][take]:.2f}" for m in labels)]
        for take, count in frames.items()
    ]
    return table(["take", "frames", *labels], rows)


def per_joint_table(summaries: Mapping[str, Summary]) -> str:
    """Rows = the 13 joints (marker or unobserved), columns = runs: mean error in cm."""
    labels = list(summaries)
    rows = [
        [
            name,
            "marker" if j in MARKER_JOINTS else "unobserved",
            *(f"{summaries[m]['per_joint_cm'][name]:.2f}" for m in labels),
        ]
        for j, name in enumerate(JOINT_NAMES)
    ]
    return table(["joint", "kind", *labels], rows)


def improvements(summaries: Mapping[str, Summary]) -> str:
    """Relative error reductions of pseudo-poses (`samba` against `chai`) and of `best`
    against `samba`, MPJPE and unobserved joints, for the pairs that were run; "" if none."""
    parts = []
    for name, new, old in (
        ("pseudo-poses (samba vs chai)", "samba", "chai"),
        ("best vs samba", "best", "samba"),
    ):
        if new in summaries and old in summaries:
            gains = [
                f"{what} {_gain(summaries[new][key], summaries[old][key]):+.1f}%"
                for what, key in (("MPJPE", "mpjpe_cm"), ("unobserved", "unobserved_cm"))
            ]
            parts.append(f"{name}: {', '.join(gains)}")
    return f"error reduction: {'; '.join(parts)}" if parts else ""


def _gain(new: object, old: object) -> float:
    """How much lower new is than old, in percent of old (positive = better)."""
    return 100.0 * (float(old) - float(new)) / float(old)


def k_sweep_table(points: Sequence[SweepPoint], summaries: Mapping[str, Summary]) -> str:
    """The paper's Fig. 8 as a table: rows = K, error (all / unobserved joints) and time."""
    rows = [
        [
            str(k),
            str(n),
            f"{summaries[label]['mpjpe_cm']:.2f}",
            f"{summaries[label]['unobserved_cm']:.2f}",
            f"{summaries[label]['frame_ms_p50']:.3f}",
            f"{summaries[label]['frame_ms_p99']:.3f}",
        ]
        for k, n, label in points
    ]
    return table(["K", "N", "MPJPE cm", "unobs cm", "p50 ms", "p99 ms"], rows)


def n_sweep_table(points: Sequence[SweepPoint], summaries: Mapping[str, Summary]) -> str:
    """The paper's Fig. 9 as a table: rows = N, for each K its MPJPE (cm) and p50 (ms)."""
    ks = sorted({k for k, _, _ in points})
    ns = sorted({n for _, n, _ in points})
    label = {(k, n): lab for k, n, lab in points}
    header = ["N", *(f"K={k} {what}" for k in ks for what in ("cm", "ms"))]
    rows = [
        [
            str(n),
            *(
                f"{summaries[label[k, n]][key]:{fmt}}"
                for k in ks
                for key, fmt in (("mpjpe_cm", ".2f"), ("frame_ms_p50", ".3f"))
            ),
        ]
        for n in ns
    ]
    return table(header, rows)
