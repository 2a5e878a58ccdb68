"""Reference joint centres: the 13 joints (`samba.body` order) computed from a full
Plug-in-Gait marker set by published rules, the ground truth against which reconstructions
of real marker takes are scored. Meters, +Y up, as `read_c3d` gives the points.

Rules, each from the markers of the same frame (NaN where one it needs is missing) and
from subject dimensions taken once per take (the median over its frames):

* Hips: Harrington ME, Zavatsky AB, Lawson SEM, Yuan Z, Theologis TN (2007). Prediction
  of the hip joint centre in adults, children, and patients with cerebral palsy based on
  magnetic resonance imaging. Journal of Biomechanics 40(3):595-602. Pelvis frame: origin
  the mid-ASIS (FWT), z from left to right ASIS, x anterior (mid-PSIS (BWT) to mid-ASIS,
  made orthogonal to z), y = z x x superior. With PW the inter-ASIS distance and PD the
  mid-ASIS to mid-PSIS distance, in mm: x = -0.24 PD - 9.9, y = -0.30 PW - 10.9,
  z = +-(0.33 PW + 7.3), + for the right hip.
* Knees and ankles: the Plug-in-Gait chord function (`chord`). Davis RB, Ounpuu S,
  Tyburski D, Gage JR (1991). A gait analysis data collection and reduction technique.
  Human Movement Science 10(5):575-587; Vicon Motion Systems, Plug-in Gait Reference
  Guide. Knee: hip centre, thigh marker THI, lateral knee KNE, offset (knee width +
  marker diameter) / 2. Ankle: knee centre, shank marker SHN, lateral malleolus ANK,
  offset (ankle width + marker diameter) / 2.
* Shoulders: Rab G, Petuskey K, Bagley A (2002). A method for determination of upper
  extremity kinematics. Gait & Posture 15(2):113-119. The glenohumeral centre lies below
  the acromion marker SHO by 17% of the acromion-acromion distance, "below" along the
  trunk's down axis: from the midpoint of C7 and CLAV to the midpoint of T10 and STRN.
* Elbows: the chord function (Plug-in Gait) from the shoulder centre and the lateral
  epicondyle ELB, offset (elbow width + marker diameter) / 2, in the plane of the
  humerus and the elbow's flexion axis. Plug-in Gait takes that axis as the normal of the
  arm plane (shoulder centre, ELB, wrist), which vanishes on a straight arm; here the
  normal's mean direction over the take's bent-arm frames (elbow angle under 150 deg), held
  in the upper-arm frame of the shoulder centre, ELB and UPA, gives the axis in every
  frame, bent or straight (the UPA side itself if the take never bends that arm).
* Wrists: the midpoint of the wrist-bar markers WRA and WRB (Plug-in Gait's wrist-bar
  point, without its offset by a wrist thickness, which is not recorded).
* Head: the centre of the four head markers LFHD, RFHD, LBHD, RBHD. That is the head's
  marker centre, not the neck/head joint of a BVH skeleton (it sits some 10 cm above and
  in front of it): score it with the evaluation's offset-removed column.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from samba.body import JOINT_INDEX
from samba.ingest.c3d_take import MarkerTake
from samba.ingest.errors import C3dError

_SIDED = {
    "asis": "FWT",
    "psis": "BWT",
    "thigh": "THI",
    "knee": "KNE",
    "shank": "SHN",
    "ankle": "ANK",
    "acromion": "SHO",
    "upper_arm": "UPA",
    "elbow": "ELB",
    "wrist_a": "WRA",
    "wrist_b": "WRB",
    "front_head": "FHD",
    "back_head": "BHD",
}
LANDMARKS: dict[str, str] = {
    **{f"{side}_{role}": f"{side.upper()}{code}" for role, code in _SIDED.items() for side in "lr"},
    "c7": "C7",
    "clavicle": "CLAV",
    "t10": "T10",
    "sternum": "STRN",
}
"""The label (Plug-in-Gait names, as CMU and Vicon use them) of each landmark the rules
read; another lab's names would be another such table."""

SHOULDER_DROP = 0.17
"""Glenohumeral centre below the acromion, as a fraction of the acromion-acromion
distance (Rab et al. 2002)."""
BENT_ELBOW = np.cos(np.radians(150.0))
"""Cosine of the elbow angle (shoulder-elbow-wrist) under which an arm counts as bent."""


@dataclass(frozen=True)
class JointWidths:
    """The subject's Plug-in-Gait measurements, meters: knee width (femoral epicondyles),
    ankle width (malleoli), elbow width (humeral epicondyles) and the marker diameter.

    The defaults are round typical adult values, for takes whose subject was not measured
    (CMU's files carry none): knee 100 mm, ankle 70 mm, elbow 70 mm, and the 14 mm
    marker Plug-in Gait assumes. An error of e in a width moves its joint centre by e/2
    along the joint's axis (5 mm per cm).
    """

    knee: float = 0.100
    ankle: float = 0.070
    elbow: float = 0.070
    marker: float = 0.014


def reference_joints(take: MarkerTake, widths: JointWidths = JointWidths()) -> np.ndarray:
    """The 13 reference joint centres (n, 13, 3) of `take`, meters, by the rules of this
    module; NaN in a frame where a marker a joint needs is missing. Raises `C3dError`
    naming the take's file and the labels it lacks."""
    m = _landmarks(take)
    knee_offset, ankle_offset, elbow_offset = (
        (width + widths.marker) / 2 for width in (widths.knee, widths.ankle, widths.elbow)
    )
    out = np.full((len(take), len(JOINT_INDEX), 3), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        down = _unit(m["t10"] + m["sternum"] - m["c7"] - m["clavicle"])  # down the trunk
        drop = SHOULDER_DROP * _take_median(m["l_acromion"] - m["r_acromion"])
        heads = [m[f"{side}_{part}_head"] for side in "lr" for part in ("front", "back")]
        out[:, JOINT_INDEX["head"]] = np.mean(heads, axis=0)
        for side, hip in zip("lr", _hips(m), strict=True):
            knee = chord(hip, m[f"{side}_thigh"], m[f"{side}_knee"], knee_offset)
            ankle = chord(knee, m[f"{side}_shank"], m[f"{side}_ankle"], ankle_offset)
            shoulder = m[f"{side}_acromion"] + drop * down
            wrist = (m[f"{side}_wrist_a"] + m[f"{side}_wrist_b"]) / 2
            elbow = _elbow(
                shoulder,
                m[f"{side}_upper_arm"],
                m[f"{side}_elbow"],
                wrist,
                1.0 if side == "l" else -1.0,
                elbow_offset,
            )
            for name, point in (
                ("hip", hip),
                ("knee", knee),
                ("foot", ankle),
                ("shoulder", shoulder),
                ("elbow", elbow),
                ("wrist", wrist),
            ):
                out[:, JOINT_INDEX[f"{side}_{name}"]] = point
    return out


def chord(joint: np.ndarray, plane: np.ndarray, marker: np.ndarray, offset: float) -> np.ndarray:
    """The Plug-in-Gait chord function: the joint centre (..., 3) in the plane of `joint`
    (the proximal joint centre), `plane` (a marker on the lateral side of the segment) and
    the lateral `marker`, at distance `offset` (meters) from `marker`, with a right angle
    joint-centre-marker (on the Thales circle over joint-marker), on the side of the line
    joint-marker away from `plane`: the medial side. NaN where `offset` is not shorter
    than joint-marker; undefined where `plane` lies on that line."""
    with np.errstate(invalid="ignore", divide="ignore"):
        along = joint - marker
        length = np.linalg.norm(along, axis=-1, keepdims=True)
        along = along / length
        medial = -_unit(_perpendicular(plane - marker, along))
        cos = offset / length
        return marker + offset * (cos * along + np.sqrt(1.0 - cos**2) * medial)


def _hips(m: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Left and right hip centres (n, 3) by Harrington et al. (2007)."""
    asis = (m["l_asis"] + m["r_asis"]) / 2
    psis = (m["l_psis"] + m["r_psis"]) / 2
    right = _unit(m["r_asis"] - m["l_asis"])
    front = _unit(_perpendicular(asis - psis, right))
    up = np.cross(right, front)
    width = _take_median(m["r_asis"] - m["l_asis"])
    depth = _take_median(asis - psis)
    back_down = (-0.24 * depth - 0.0099) * front + (-0.30 * width - 0.0109) * up
    out = (0.33 * width + 0.0073) * right
    return asis + back_down - out, asis + back_down + out


def _elbow(
    shoulder: np.ndarray,
    upper_arm: np.ndarray,
    elbow: np.ndarray,
    wrist: np.ndarray,
    lateral_sign: float,
    offset: float,
) -> np.ndarray:
    """Elbow centres (n, 3) by the chord function in the plane of the humerus and the
    flexion axis: the arm plane's lateral normal averaged over the bent frames in the
    upper-arm frame (module docstring). `lateral_sign` is +1 for the left arm, -1 the
    right."""
    humerus = _unit(shoulder - elbow)
    outward = _unit(_perpendicular(upper_arm - elbow, humerus))  # towards UPA
    forward = np.cross(humerus, outward)
    normal = lateral_sign * _unit(np.cross(shoulder - elbow, wrist - elbow))  # lateral
    local = np.stack([(normal * outward).sum(-1), (normal * forward).sum(-1)], axis=-1)
    bent = np.sum(humerus * _unit(wrist - elbow), axis=-1) > BENT_ELBOW
    bent &= np.isfinite(local).all(axis=-1)
    axis = local[bent].mean(axis=0) if bent.any() else np.array([1.0, 0.0])
    lateral = axis[0] * outward + axis[1] * forward
    return chord(shoulder, elbow + lateral, elbow, offset)


def _landmarks(take: MarkerTake) -> dict[str, np.ndarray]:
    """Trajectories (n, 3) of the `LANDMARKS`, by role; `C3dError` naming the lacking."""
    index = {label.lower(): i for i, label in enumerate(take.labels)}
    lacking = [label for label in LANDMARKS.values() if label.lower() not in index]
    if lacking:
        raise C3dError(
            take.source,
            f"the reference joint centres need the labels {', '.join(lacking)}, "
            "which the take lacks",
        )
    return {role: take.points[:, index[label.lower()]] for role, label in LANDMARKS.items()}


def _take_median(vectors: np.ndarray) -> float:
    """Median over the take of the lengths of `vectors` (n, 3), NaN where all missing."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all frames missing: NaN
        return float(np.nanmedian(np.linalg.norm(vectors, axis=-1)))


def _perpendicular(vectors: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """The part of `vectors` (..., 3) perpendicular to the unit vectors `unit` (..., 3)."""
    return vectors - np.sum(vectors * unit, axis=-1, keepdims=True) * unit


def _unit(vectors: np.ndarray) -> np.ndarray:
    """`vectors` (..., 3) scaled to length 1 (NaN for zero vectors)."""
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)
