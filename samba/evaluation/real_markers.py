"""Accuracy on real marker takes (`samba eval --test FILE.c3d`).

A real take comes with its skin markers (the 8 of a marker set) and reference joint
centres computed from its full marker set by published rules (`samba.ingest.
reference_joints`). Every method reconstructs it three ways, scored against the
reference joint centres:

* `raw`: the real skin markers;
* `calibrated`: the same markers with the subject's skin offsets removed
  (`samba.reconstruct.calibrate_skin_offsets` over the calibration stretch, then
  `SkinMarkerReconstructor`);
* `synthetic`: markers placed exactly at the reference joint centres (what the
  synthetic protocol measures), so the real-versus-synthetic gap is one line.

The markers go through the evaluation cameras (projected, noised, triangulated:
`samba.markers.observe_markers`) unless `markers_3d`. Errors are in cm at the subject's
own size (real joints: no tibia scaling). Because the database's joints (BVH joint
centres) and anatomical joint centres are defined differently, every error is also
given after removing each joint's mean offset in its segment's frame
(`offset_removed_errors`), beside the raw one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from samba.base import InputError
from samba.body import JOINT_NAMES, MARKER_JOINTS, UNOBSERVED_JOINTS, joint_frames, markers_of
from samba.evaluation.experiment import DatabaseIndexes, IndexBuilder, NamedPoses
from samba.evaluation.protocol import CapturedTake, TakeErrors, run_method
from samba.evaluation.report import table
from samba.markers import evaluation_cameras, observe_markers
from samba.reconstruct import (
    Method,
    Reconstructor,
    SkinMarkerReconstructor,
    SkinOffsets,
    calibrate_skin_offsets,
)

VARIANTS: tuple[str, ...] = ("raw", "calibrated", "synthetic")
"""How each real take is reconstructed (module docstring)."""
VARIANT_WORDS = {
    "raw": "real markers",
    "calibrated": "real, calibrated",
    "synthetic": "at reference centres",
}


@dataclass(frozen=True)
class MarkerTest:
    """A real marker take to score: `truth` (F, 13, 3) reference joint centres, `markers`
    (F, 8, 3) its skin markers, meters, NaN = missing, at 30 fps."""

    name: str
    truth: np.ndarray
    markers: np.ndarray


@dataclass(frozen=True)
class RealTakeErrors:
    """One real take reconstructed one way: `scored` as the protocol scores it (errors
    against the reference joint centres), `removed` (F, 13) meters the errors after
    `offset_removed_errors`."""

    scored: TakeErrors
    removed: np.ndarray

    @classmethod
    def of(
        cls, reconstructor: Reconstructor | SkinMarkerReconstructor, take: CapturedTake
    ) -> RealTakeErrors:
        """Run `reconstructor` over `take` (`run_method`) and score it both ways."""
        scored = run_method(reconstructor, take)
        return cls(scored, offset_removed_errors(scored.poses, take.truth))


@dataclass(frozen=True)
class MarkerEvaluation:
    """The outcome of `evaluate_markers`: per run label and variant, the errors of every
    test take in order; per run label and take, the calibrated skin offsets."""

    results: dict[str, dict[str, list[RealTakeErrors]]]
    offsets: dict[str, dict[str, SkinOffsets]]
    test_frames: dict[str, int]
    train: tuple[str, ...]
    seed: int
    calibration: tuple[int, int]
    markers_3d: bool

    def summaries(self) -> dict[str, dict[str, dict[str, object]]]:
        """`summarize_real` of every run and variant."""
        return {
            label: {variant: summarize_real(takes) for variant, takes in runs.items()}
            for label, runs in self.results.items()
        }


def evaluate_markers(
    train: Sequence[NamedPoses],
    tests: Sequence[MarkerTest],
    runs: Mapping[str, Method],
    build_index: IndexBuilder,
    seed: int = 0,
    calibration: tuple[int, int] = (0, 60),
    markers_3d: bool = False,
    progress: bool | None = False,
) -> MarkerEvaluation:
    """Reconstruct every real test take with every run in the three `VARIANTS`; the
    database is every training take (plus mirror images for methods that want them).
    `calibration` is the (start, stop) frame range of the subject calibration; test
    take i is captured with seed `seed + i`. `InputError` for an empty database or a
    calibration range outside a take."""
    if not train:
        raise InputError("--train", "no training take given")
    indexes = DatabaseIndexes(np.concatenate([poses for _, poses in train]), build_index)
    results: dict[str, dict[str, list[RealTakeErrors]]] = {
        label: {v: [] for v in VARIANTS} for label in runs
    }
    offsets: dict[str, dict[str, SkinOffsets]] = {label: {} for label in runs}
    start, stop = calibration
    bar = tqdm(tests, unit="take", disable=None if progress is None else not progress)
    for number, test in enumerate(bar):
        bar.set_postfix_str(test.name, refresh=False)
        if stop > len(test.markers) or start >= stop:
            raise InputError(
                "--calibration",
                f"frames {start}-{stop} are outside {test.name} ({len(test.markers)} frames)",
            )
        skin = observe(test.truth, test.markers, seed + number, markers_3d)
        exact = observe(test.truth, markers_of(test.truth), seed + number, markers_3d)
        for label, m in runs.items():
            reconstructor = m.build(indexes.get(m.mirrored_database))
            subject = calibrate_skin_offsets(reconstructor, skin[start:stop])
            offsets[label][test.name] = subject
            seen = CapturedTake(test.name, test.truth, skin)
            at_centres = CapturedTake(test.name, test.truth, exact)
            calibrated = SkinMarkerReconstructor(reconstructor, subject)
            results[label]["raw"].append(RealTakeErrors.of(reconstructor, seen))
            results[label]["calibrated"].append(RealTakeErrors.of(calibrated, seen))
            results[label]["synthetic"].append(RealTakeErrors.of(reconstructor, at_centres))
    frames = {test.name: len(test.markers) for test in tests}
    names = tuple(name for name, _ in train)
    return MarkerEvaluation(results, offsets, frames, names, seed, calibration, markers_3d)


def observe(truth: np.ndarray, markers: np.ndarray, seed: int, markers_3d: bool) -> np.ndarray:
    """Markers (F, 8, 3) meters as the evaluation cameras placed for the reference joints
    truth (F, 13, 3) see and triangulate them (seeded), or as they are with `markers_3d`."""
    if markers_3d:
        return np.asarray(markers, dtype=np.float64)
    carrier = np.array(truth, dtype=np.float64)
    carrier[:, list(MARKER_JOINTS)] = markers
    rng = np.random.default_rng(seed)
    return observe_markers(carrier, evaluation_cameras(truth), rng).markers


def offset_removed_errors(poses: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Joint errors (F, 13) meters of poses (F, 13, 3) against truth (F, 13, 3) after
    removing each joint's mean error in the frame of its segment on the truth
    (`samba.body.joint_frames`): what is left once a constant difference of definition
    between the two kinds of joint centre is taken out."""
    frames = joint_frames(truth)
    local = np.einsum("fkji,fkj->fki", frames, poses - truth)
    local = local - np.nanmean(local, axis=0)
    return np.linalg.norm(local, axis=-1)


def summarize_real(takes: Sequence[RealTakeErrors]) -> dict[str, object]:
    """Pooled errors of real takes in cm (unscaled; frames without reference joint
    centres left out): all joints, marker joints, unobserved joints and per joint, raw
    and with the mean segment-frame offsets removed (`_removed`); predicted frames."""
    raw = np.concatenate([t.scored.errors for t in takes]) * 100.0
    removed = np.concatenate([t.removed for t in takes]) * 100.0
    out: dict[str, object] = {"frames": len(raw)}
    for suffix, errors in (("", raw), ("_removed", removed)):
        out[f"mpjpe_cm{suffix}"] = float(np.nanmean(errors))
        out[f"marker_cm{suffix}"] = float(np.nanmean(errors[:, list(MARKER_JOINTS)]))
        out[f"unobserved_cm{suffix}"] = float(np.nanmean(errors[:, list(UNOBSERVED_JOINTS)]))
        out[f"per_joint_cm{suffix}"] = {
            name: float(np.nanmean(errors[:, j])) for j, name in enumerate(JOINT_NAMES)
        }
    out["predicted_frames"] = int(sum(t.scored.predicted.sum() for t in takes))
    out["per_take_cm"] = {t.scored.name: float(np.nanmean(t.scored.errors) * 100.0) for t in takes}
    return out


def marker_report(evaluation: MarkerEvaluation) -> str:
    """The text report of the real takes: the setting, per run and variant the errors
    (all, marker and unobserved joints, raw and offset-removed), the calibrated over
    synthetic ratio, per-joint errors and the skin offsets found per take."""
    summaries = evaluation.summaries()
    frames = sum(evaluation.test_frames.values())
    start, stop = evaluation.calibration
    seen = "as recorded (3D)" if evaluation.markers_3d else "through the evaluation cameras"
    takes = ", ".join(f"{name} ({n} frames)" for name, n in evaluation.test_frames.items())
    lines = [
        f"real marker takes: {takes}; {frames} frames at 30 fps",
        f"{len(evaluation.train)} training takes; markers {seen}; seed {evaluation.seed}; "
        f"subject calibration over frames {start}-{stop - 1}",
        "errors in cm against the reference joint centres, the subject's own size; "
        "'-offset' columns: each joint's mean offset in its segment's frame removed\n",
    ]
    header = [
        "method",
        "markers",
        "all",
        "marker",
        "unobs",
        "all-offset",
        "marker-offset",
        "unobs-offset",
        "predicted",
    ]
    rows = []
    for label, variants in summaries.items():
        for variant, s in variants.items():
            rows.append(
                [
                    label,
                    VARIANT_WORDS[variant],
                    *(f"{s[key]:.2f}" for key in ("mpjpe_cm", "marker_cm", "unobserved_cm")),
                    *(
                        f"{s[key]:.2f}"
                        for key in (
                            "mpjpe_cm_removed",
                            "marker_cm_removed",
                            "unobserved_cm_removed",
                        )
                    ),
                    str(s["predicted_frames"]),
                ]
            )
    lines.append(table(header, rows))
    ratios = [
        f"{label} {v['calibrated']['mpjpe_cm'] / v['synthetic']['mpjpe_cm']:.2f}x"
        for label, v in summaries.items()
    ]
    lines.append(f"\ncalibrated real over synthetic markers (all joints): {', '.join(ratios)}")
    columns = [(label, variant) for label in summaries for variant in VARIANTS]
    joint_header = ["joint", *(f"{label} {variant}" for label, variant in columns)]
    for suffix, title in (("", "per joint (cm)"), ("_removed", "per joint, offset removed (cm)")):
        joint_rows = [
            [
                name,
                *(
                    f"{summaries[label][variant][f'per_joint_cm{suffix}'][name]:.2f}"
                    for label, variant in columns
                ),
            ]
            for name in JOINT_NAMES
        ]
        lines.append(f"\n{title}\n{table(joint_header, joint_rows)}")
    for label, per_take in evaluation.offsets.items():
        for name, offsets in per_take.items():
            lines.append(f"\nskin offsets of {name} ({label}; x left, y up the segment, z forward)")
            lines.append(offsets.report())
    return "\n".join(lines)


def marker_document(evaluation: MarkerEvaluation) -> dict[str, object]:
    """The real takes' part of the `samba eval` JSON document."""
    return {
        "test": evaluation.test_frames,
        "seed": evaluation.seed,
        "calibration_frames": list(evaluation.calibration),
        "markers_3d": evaluation.markers_3d,
        "methods": evaluation.summaries(),
        "skin_offsets": {
            label: {name: offsets.as_dict() for name, offsets in per_take.items()}
            for label, per_take in evaluation.offsets.items()
        },
    }
