"""Procedural motions on the 13-joint skeleton: the pose database when no real data is there.

Every take is built by forward kinematics from joint angles over time, vectorised over
frames. The pelvis (hip midpoint) carries yaw and roll; a torso of fixed length rises to
the shoulder midpoint with lean, side bend and twist; the head sits `neck` above it. Arms
have 2-DOF shoulders (flexion, abduction, plus a humeral rotation that only turns the
elbow's bending plane) and hinge elbows; legs have 2-DOF hips and hinge knees. Leg angles
come from an analytic inverse kinematics of planned ankle paths, so stance feet stay put
on the floor while the body travels, turns or squats. Each take is then lifted so the
lower ankle is at y = 0 (higher during the flight phases of running and jumping jacks),
turned to a random heading and moved to a random start on the floor.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass, fields
from functools import partial
from typing import NamedTuple

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.spatial.transform import Rotation

from samba.body import N_JOINTS, Body, Take

MOTIONS: tuple[str, ...] = (
    "walk",
    "run",
    "jumping_jacks",
    "arm_swing",
    "squat",
    "kick",
    "wave",
    "turn",
    "golf_swing",
    "point",
)

_SEGMENTS: tuple[str, ...] = tuple(f.name for f in fields(Body) if f.name != "height")
_REF_LEG = (0.245 + 0.246) * 1.70
"""Hip-to-ankle length (m) of the average 1.70 m body; gaits scale with it (Froude)."""
_MAX_HINGE = np.radians(150.0)
_MAX_IK_KNEE = np.radians(135.0)
_SIDES = (1.0, -1.0)
"""Mirror factor of the left and the right side along the body's left (+X) axis."""


@dataclass(frozen=True)
class _Setup:
    """The inputs of a motion: frame times `t` (n,) s, body, speed factor, start phase."""

    t: np.ndarray
    body: Body
    speed: float
    phase: float
    rng: np.random.Generator

    @property
    def leg(self) -> float:
        """Hip-to-ankle length (m) of the straight leg."""
        return self.body.thigh + self.body.shin

    def cycle(self, hz: float) -> np.ndarray:
        """Cycle phase (n,) of a rhythm of `hz` at speed factor 1, from the start phase."""
        return hz * self.speed * self.t + self.phase


@dataclass
class _Plan:
    """What a motion asks for, in the take's local frame (facing +Z), radians and meters.

    Per-frame arrays have shape (n,); per-side arrays (2, n), left side first. `pelvis`
    (n, 3) is the hip midpoint, `feet` (2, n, 3) the ankle targets the legs reach for,
    `hip_flex_add`/`knee_add` leg angles added after the inverse kinematics (kicks) and
    `hop` (n,) the height of the lower ankle above the floor.
    """

    pelvis: np.ndarray
    yaw: np.ndarray
    roll: np.ndarray
    lean: np.ndarray
    bend: np.ndarray
    twist: np.ndarray
    nod: np.ndarray
    hop: np.ndarray
    arm_flex: np.ndarray
    arm_abd: np.ndarray
    arm_rot: np.ndarray
    elbow: np.ndarray
    hip_flex_add: np.ndarray
    knee_add: np.ndarray
    feet: np.ndarray

    @classmethod
    def rest(cls, m: _Setup) -> _Plan:
        """Standing upright with the feet under the hips and the arms hanging relaxed."""
        n = len(m.t)
        per_frame = {k: np.zeros(n) for k in ("yaw", "roll", "lean", "bend", "twist", "nod", "hop")}
        per_side = {
            k: np.zeros((2, n)) for k in ("arm_flex", "arm_rot", "hip_flex_add", "knee_add")
        }
        plan = cls(
            pelvis=np.zeros((n, 3)),
            arm_abd=np.full((2, n), np.radians(8.0)),
            elbow=np.full((2, n), np.radians(12.0)),
            feet=np.zeros((2, n, 3)),
            **per_frame,
            **per_side,
        )
        plan.feet[:, :, 0] = np.array(_SIDES)[:, None] * m.body.hip_width / 2
        return plan


def random_body(rng: np.random.Generator) -> Body:
    """A random subject: stature uniform in 1.50..1.95 m, each segment scaled by 0.9..1.1."""
    height = rng.uniform(1.50, 1.95)
    factors = {name: rng.uniform(0.9, 1.1) for name in _SEGMENTS}
    return Body.from_height(height).scaled(factors)


def random_standing(
    rng: np.random.Generator, offset_m: float = 1.0, turn_deg: float = 50.0
) -> np.ndarray:
    """A `random_body` in the standard pose (13, 3) meters, arms 10..70 degrees from
    vertical, standing within `offset_m` of the origin in x and z, facing +Z turned by
    up to `turn_deg` about +Y."""
    pose = random_body(rng).standard_pose(rng.uniform(10.0, 70.0))
    pose = Rotation.from_euler("y", rng.uniform(-turn_deg, turn_deg), degrees=True).apply(pose)
    pose[:, [0, 2]] += rng.uniform(-offset_m, offset_m, 2)
    return pose


def _reach(body: Body, knee_deg: float | np.ndarray) -> float | np.ndarray:
    """Hip-to-ankle distance (m) of a leg whose knee is flexed by `knee_deg` degrees."""
    th, sh = body.thigh, body.shin
    return np.sqrt(th**2 + sh**2 + 2 * th * sh * np.cos(np.radians(knee_deg)))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _window(ph: np.ndarray, start: float) -> np.ndarray:
    """Progress 0..1 (n,) through the part of each cycle of `ph` after `start`, else 0."""
    return np.clip((ph - np.floor(ph) - start) / (1.0 - start), 0.0, 1.0)


def _hop(flight: np.ndarray, speed: float) -> np.ndarray:
    """Parabolic hop (n,) m over `flight` progress 0..1, 7 cm high at speed factor 1."""
    return np.clip(0.07 * speed, 0.05, 0.15) * 4.0 * flight * (1.0 - flight)


def _gait(ph: np.ndarray, duty: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stepping cycle of one foot at cycle phase `ph` (n,), stance for a `duty` fraction.

    Returns the phase u in [0, 1) (stance first), the swing progress s in [0, 1] and the
    foot's position along the travel relative to the body's mean progress, in cycles:
    it moves back at exactly the body's pace in stance and forward smoothly in swing.
    """
    u = ph - np.floor(ph)
    s = _window(ph, duty)
    return u, s, _smoothstep(s) + duty / 2 - u


def _rot(axis: int, angle: np.ndarray) -> np.ndarray:
    """Right-handed rotations (n, 3, 3) by `angle` (n,) radians about axis 0, 1 or 2."""
    i, j = ((1, 2), (2, 0), (0, 1))[axis]
    r = np.zeros((len(angle), 3, 3))
    r[:, axis, axis] = 1.0
    r[:, i, i] = r[:, j, j] = np.cos(angle)
    r[:, j, i] = np.sin(angle)
    r[:, i, j] = -r[:, j, i]
    return r


def _hips(plan: _Plan, body: Body) -> tuple[np.ndarray, np.ndarray]:
    """Pelvis rotations (n, 3, 3) and hip joints (2, n, 3) of the plan."""
    r = _rot(1, plan.yaw) @ _rot(2, plan.roll)
    return r, np.stack([plan.pelvis + sx * body.hip_width / 2 * r[:, :, 0] for sx in _SIDES])


def _pelvis_height(plan: _Plan, body: Body, knee_deg: float | np.ndarray) -> np.ndarray:
    """Highest pelvis height (n,) m from which both legs, flexing the knee by at least
    `knee_deg` degrees, reach their ankle targets (a 1 mm soft minimum over the two legs)."""
    _, hips = _hips(plan, body)
    horizontal = ((plan.feet - hips)[..., [0, 2]] ** 2).sum(axis=-1)
    vertical = np.sqrt(np.clip(_reach(body, knee_deg) ** 2 - horizontal, 0.0, None))
    height = plan.feet[..., 1] + vertical - (hips[..., 1] - plan.pelvis[:, 1])
    return -1e-3 * np.logaddexp(-height[0] / 1e-3, -height[1] / 1e-3)


def _leg_ik(p: np.ndarray, l1: float, l2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hip flexion, hip abduction and knee flexion (n,) placing the ankle at `p` (n, 3).

    `p` is the hip-to-ankle vector of a left leg in the pelvis frame; this inverts the
    leg's forward kinematics in `_forward`. Out-of-reach targets are pulled onto the
    reachable shell.
    """
    dist = np.linalg.norm(p, axis=1)
    lo = np.sqrt(l1**2 + l2**2 + 2 * l1 * l2 * np.cos(_MAX_IK_KNEE))
    reach = np.clip(dist, lo, (l1 + l2) * (1.0 - 1e-9))
    p = p * (reach / dist)[:, None]
    cos_knee = np.clip((reach**2 - l1**2 - l2**2) / (2 * l1 * l2), -1.0, 1.0)
    knee = np.arccos(cos_knee)
    along, across = l1 + l2 * cos_knee, l2 * np.sin(knee)
    abd = np.arcsin(np.clip(p[:, 0] / along, -1.0, 1.0))
    flex = np.arctan2(p[:, 2], -p[:, 1]) + np.arctan2(across, along * np.cos(abd))
    return flex, abd, knee


def _limb_axes(flex: np.ndarray, abd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upper-segment direction and the flexed forward axis (n, 3) of a left limb.

    The limb hangs down (-Y) at zero angles; abduction swings it out to +X in the frontal
    plane, then flexion swings it forward (+Z) about the body's left axis.
    """
    ca = np.cos(abd)
    d = np.stack([np.sin(abd), -ca * np.cos(flex), ca * np.sin(flex)], axis=-1)
    f = np.stack([np.zeros_like(flex), np.sin(flex), np.cos(flex)], axis=-1)
    return d, f


def _forward(plan: _Plan, body: Body) -> np.ndarray:
    """Poses (n, 13, 3) m in the local frame; leg angles by inverse kinematics of the plan."""
    r_pelvis, hips = _hips(plan, body)
    r_chest = r_pelvis @ _rot(1, plan.twist) @ _rot(0, plan.lean) @ _rot(2, plan.bend)
    poses = np.zeros((len(plan.yaw), N_JOINTS, 3))
    neck_base = plan.pelvis + body.torso * r_chest[:, :, 1]
    poses[:, 0] = neck_base + body.neck * (r_chest @ _rot(0, plan.nod))[:, :, 1]
    for i, sx in enumerate(_SIDES):
        mirror = np.array([sx, 1.0, 1.0])
        shoulder = neck_base + sx * body.shoulder_width / 2 * r_chest[:, :, 0]
        arm_d, arm_f = _limb_axes(plan.arm_flex[i], plan.arm_abd[i])
        humeral = plan.arm_rot[i][:, None]
        arm_b = np.cos(humeral) * arm_f + np.sin(humeral) * np.cross(arm_f, arm_d)
        p = np.einsum("nji,nj->ni", r_pelvis, plan.feet[i] - hips[i]) * mirror
        flex, abd, knee = _leg_ik(p, body.thigh, body.shin)
        leg_d, leg_f = _limb_axes(flex + plan.hip_flex_add[i], abd)
        limbs = (
            (1, shoulder, r_chest, arm_d, arm_b, plan.elbow[i], body.upper_arm, body.forearm),
            (7, hips[i], r_pelvis, leg_d, -leg_f, knee + plan.knee_add[i], body.thigh, body.shin),
        )
        for joint, root, r, d, b, hinge, l1, l2 in limbs:
            d, b = (np.einsum("nij,nj->ni", r, v * mirror) for v in (d, b))
            hinge = np.clip(hinge, 0.0, _MAX_HINGE)[:, None]
            mid = root + l1 * d
            poses[:, [joint + i, joint + 2 + i, joint + 4 + i]] = np.stack(
                [root, mid, mid + l2 * (np.cos(hinge) * d + np.sin(hinge) * b)], axis=1
            )
    return poses


def _stepping_feet(
    plan: _Plan, ph: np.ndarray, duty: float, stride: float, lift: float, heel: float = 0.0
) -> None:
    """Ankle targets of alternating steps of `stride` m per cycle along +Z, the right foot
    half a cycle behind the left, lifted `lift` m in swing. Walking (duty > 0.5) raises
    the heel `heel` m at push-off once the other foot has landed: one ankle stays down."""
    for i in range(2):
        u, s, rel = _gait(ph + 0.5 * i, duty)
        plan.feet[i, :, 1] = lift * np.sin(np.pi * s)
        plan.feet[i, :, 2] = plan.pelvis[:, 2] + stride * rel
        if heel:
            push = np.where(u < duty, _smoothstep((u - 0.5) / (duty - 0.5)), 1.0 - _smoothstep(s))
            plan.feet[i, :, 1] += heel * push


def _locomotion(m: _Setup, run: bool) -> _Plan:
    """Walking (1.2 m/s, 1 stride/s) or running (3 m/s, 1.4 strides/s, with flight) along
    +Z, at speed factor 1 and average leg length; longer legs go faster in fewer strides."""
    plan = _Plan.rest(m)
    froude = np.sqrt(m.leg / _REF_LEG)
    hz, v, duty = (1.4, 3.0, 0.3) if run else (1.0, 1.2, 0.6)
    ph = m.cycle(hz / froude)
    w = 2 * np.pi * ph
    plan.pelvis[:, 2] = v * froude * m.speed * m.t
    plan.pelvis[:, 0] = (0.01 if run else 0.02) * np.sin(w)
    plan.yaw = np.radians(-7.0 if run else -5.0) * np.cos(w)
    plan.roll = np.radians(4.0 if run else 3.0) * np.sin(w)
    plan.twist, plan.bend = -1.5 * plan.yaw, -plan.roll
    plan.lean = np.radians(10.0 if run else 4.0) + np.radians(2.0) * np.cos(2 * w)
    plan.nod = np.radians(2.0) * np.cos(2 * w)
    stride = v * froude**2 / hz
    swing = np.stack([-np.cos(w), np.cos(w)])
    if run:
        _stepping_feet(plan, ph, duty, stride, lift=0.28 * m.leg)
        plan.pelvis[:, 1] = _pelvis_height(plan, m.body, 12.0).min()
        flight = _window(2 * ph, 2 * duty)
        plan.hop = _hop(flight, m.speed)
        plan.arm_flex, plan.elbow = np.radians(15.0 + 35.0 * swing), np.radians(85.0 + 10.0 * swing)
        plan.arm_abd[:] = np.radians(12.0)
    else:
        _stepping_feet(plan, ph, duty, stride, lift=0.10 * m.leg, heel=0.08 * m.leg)
        highest = _pelvis_height(plan, m.body, 12.0)
        low, high = highest.min(), highest.max()
        landing = 0.5 + 0.5 * np.cos(4 * np.pi * ph)
        plan.pelvis[:, 1] = np.minimum(highest, high - (high - low) * landing)
        plan.arm_flex, plan.elbow = np.radians(5.0 + 20.0 * swing), np.radians(20.0 + 10.0 * swing)
    return plan


def _jumping_jacks(m: _Setup) -> _Plan:
    """Hop out to a wide stance with the arms overhead and back in, 0.9 cycles/s."""
    plan = _Plan.rest(m)
    ph, contact = m.cycle(0.9), 0.45
    flight = _window(2 * ph, contact)
    out = np.floor(2 * ph) % 2 == 0
    spread = np.where(out, _smoothstep(flight), 1.0 - _smoothstep(flight))
    plan.feet[:, :, 0] *= 1.0 + 0.6 * m.leg / m.body.hip_width * spread
    q = 2 * ph - np.floor(2 * ph)
    absorb = np.where(q < contact, np.sin(np.pi * q / contact), 0.0)
    plan.pelvis[:, 1] = _pelvis_height(plan, m.body, 8.0 + 20.0 * absorb)
    plan.hop = _hop(flight, m.speed)
    arms_up = 0.5 - 0.5 * np.cos(2 * np.pi * (ph - 0.11))
    plan.arm_abd[:] = np.radians(6.0 + 150.0 * arms_up)
    plan.elbow[:] = np.radians(10.0 + 15.0 * np.sin(np.pi * arms_up))
    plan.lean, plan.nod = np.radians(3.0 * absorb), np.radians(-4.0 * arms_up)
    return plan


def _arm_swing(m: _Setup) -> _Plan:
    """Both arms swinging ±60° forward and back, together or alternating, feet planted."""
    plan = _Plan.rest(m)
    together = bool(m.rng.integers(2))
    w = 2 * np.pi * m.cycle(0.7)
    swing = np.stack([np.sin(w), np.sin(w) if together else -np.sin(w)])
    plan.arm_flex = np.radians(60.0) * swing
    plan.elbow = np.radians(10.0 + 25.0 * np.clip(swing, 0.0, 1.0))
    plan.arm_abd[:] = np.radians(10.0)
    plan.pelvis[:, 1] = _pelvis_height(plan, m.body, 8.0 + 6.0 * np.sin(w) ** 2)
    if together:
        plan.lean = np.radians(-4.0) * np.sin(w)
    else:
        plan.twist = np.radians(-6.0) * np.sin(w)
    plan.nod = np.radians(2.0) * np.sin(w)
    return plan


def _squat(m: _Setup) -> _Plan:
    """Squats to about 100° of knee flexion, hips back, torso forward, arms raised forward."""
    plan = _Plan.rest(m)
    depth = 0.5 - 0.5 * np.cos(2 * np.pi * m.cycle(0.4))
    plan.feet[:, :, 0] += np.array(_SIDES)[:, None] * 0.05 * m.leg
    plan.pelvis[:, 2] = -0.24 * m.leg * depth
    plan.pelvis[:, 1] = _pelvis_height(plan, m.body, 6.0 + 96.0 * depth)
    plan.lean = np.radians(40.0) * depth
    plan.nod = -0.6 * plan.lean
    plan.arm_flex[:] = np.radians(5.0 + 80.0 * depth)
    return plan


def _kick(m: _Setup) -> _Plan:
    """Alternating front kicks: chamber, snap the knee straight at 80° hip flexion, recoil."""
    plan = _Plan.rest(m)
    ph = 2 * m.cycle(0.55)
    kicking_left = (np.floor(ph) + m.rng.integers(2)) % 2 == 0
    s = np.clip((ph - np.floor(ph) - 0.1) / 0.8, 0.0, 1.0)
    ramp = np.sin(np.pi * s)
    knee = np.radians(140.0) * ramp**2 * (1.0 - np.exp(-(((s - 0.5) / 0.15) ** 2)))
    for i, kicking in enumerate((kicking_left, ~kicking_left)):
        plan.hip_flex_add[i] = np.where(kicking, np.radians(80.0) * ramp**2, 0.0)
        plan.knee_add[i] = np.where(kicking, knee, 0.0)
        plan.arm_flex[i] = np.radians(25.0 + np.where(kicking, -15.0, 30.0) * ramp**2)
    side = np.where(kicking_left, 1.0, -1.0)
    plan.pelvis[:, 0] = -side * 0.045 * ramp
    plan.roll = np.radians(3.0) * side * ramp
    plan.pelvis[:, 1] = _pelvis_height(plan, m.body, 8.0 + 12.0 * ramp)
    plan.lean = np.radians(-12.0) * ramp**2
    plan.arm_abd[:] = np.radians(15.0 + 30.0 * ramp)
    plan.elbow[:] = np.radians(70.0)
    return plan


def _wave(m: _Setup) -> _Plan:
    """One arm (left or right at random) raised and waving 1.6 times a second."""
    plan = _Plan.rest(m)
    arm = int(m.rng.integers(2))
    wave = np.sin(2 * np.pi * m.cycle(1.6))
    plan.arm_abd[arm], plan.arm_flex[arm] = np.radians(115.0), np.radians(-10.0)
    plan.arm_rot[arm] = np.radians(80.0 + 10.0 * wave)
    plan.elbow[arm] = np.radians(55.0 + 30.0 * wave)
    shift = np.sin(2 * np.pi * m.cycle(0.25))
    plan.pelvis[:, 0] = 0.03 * shift
    plan.roll = np.radians(2.0) * shift
    plan.bend = np.radians(-3.0) * shift + np.radians(4.0) * _SIDES[arm]
    plan.pelvis[:, 1] = _pelvis_height(plan, m.body, 8.0)
    return plan


def _turn(m: _Setup) -> _Plan:
    """Turning in place at 90°/s (left or right at random) in small steps, 1.1 steps/s."""
    plan = _Plan.rest(m)
    omega = np.radians(90.0) * m.speed * (1.0 if m.rng.integers(2) else -1.0)
    ph, duty = m.cycle(1.1), 0.6
    plan.yaw = omega * m.t
    for i, sx in enumerate(_SIDES):
        _, s, rel = _gait(ph + 0.5 * i, duty)
        foot_yaw = plan.yaw + omega / (1.1 * m.speed) * rel
        plan.feet[i, :, 0] = sx * m.body.hip_width / 2 * np.cos(foot_yaw)
        plan.feet[i, :, 1] = 0.06 * m.leg * np.sin(np.pi * s)
        plan.feet[i, :, 2] = -sx * m.body.hip_width / 2 * np.sin(foot_yaw)
    plan.pelvis[:, 1] = _pelvis_height(plan, m.body, 10.0)
    plan.twist[:] = np.sign(omega) * np.radians(8.0)
    plan.arm_flex = np.radians(8.0) * np.stack([-np.cos(2 * np.pi * ph), np.cos(2 * np.pi * ph)])
    plan.elbow[:] = np.radians(18.0)
    return plan


class _GolfKey(NamedTuple):
    """The angles of a golf swing's key pose in degrees, or (n,) arrays of them over frames
    in radians. `tilt` leans the spine toward the ball (+Z) whatever the shoulders' turn;
    `_l`/`_r` are the left/right arm."""

    yaw: float | np.ndarray
    twist: float | np.ndarray
    tilt: float | np.ndarray
    nod: float | np.ndarray
    knee: float | np.ndarray
    flex_l: float | np.ndarray
    flex_r: float | np.ndarray
    abd_l: float | np.ndarray
    abd_r: float | np.ndarray
    elbow_l: float | np.ndarray
    elbow_r: float | np.ndarray


_GOLF_KEYS: dict[str, _GolfKey] = {
    "address": _GolfKey(0.0, 0.0, 35.0, 25.0, 20.0, 30.0, 40.0, -15.0, -18.0, 20.0, 10.0),
    "top": _GolfKey(-40.0, -50.0, 30.0, 20.0, 18.0, 90.0, 60.0, -50.0, 27.0, 10.0, 90.0),
    "impact": _GolfKey(25.0, -15.0, 33.0, 25.0, 22.0, 30.0, 40.0, -15.0, -17.0, 15.0, 10.0),
    "finish": _GolfKey(70.0, 35.0, 10.0, 0.0, 15.0, 70.0, 105.0, -12.0, -34.0, 85.0, 15.0),
}
"""Key poses with the grip (both wrists within about 10 cm) below the chest at address
and impact, over the right shoulder at the top and over the left one at the finish."""
_GOLF_SCHEDULE: tuple[tuple[float, str], ...] = (
    (0.0, "address"),
    (0.15, "address"),
    (0.42, "top"),
    (0.46, "top"),
    (0.52, "impact"),
    (0.60, "finish"),
    (0.75, "finish"),
    (0.95, "address"),
    (1.0, "address"),
)
"""Cycle phase of each key pose: a pause at address, backswing, a short stop at the top,
a fast downswing through impact to the finish, a hold, and back to address."""


def _golf_swing(m: _Setup) -> _Plan:
    """A right-handed golf swing 0.35 times a second, the target at +X: address bent at
    the hips, backswing with the hands over the right shoulder, downswing, follow-through
    to the hands over the left shoulder, the pelvis turning and sliding with the swing.
    Monotone cubic interpolation of the key poses: smooth, no overshoot, still in holds."""
    plan = _Plan.rest(m)
    times = [t for t, _ in _GOLF_SCHEDULE]
    table = np.array([_GOLF_KEYS[name] for _, name in _GOLF_SCHEDULE])
    ph = m.cycle(0.35)
    k = _GolfKey(*np.radians(PchipInterpolator(times, table)(ph - np.floor(ph))).T)
    heading = k.yaw + k.twist
    plan.yaw, plan.twist, plan.nod = k.yaw, k.twist, k.nod
    plan.lean, plan.bend = k.tilt * np.cos(heading), k.tilt * np.sin(heading)
    plan.arm_flex = np.stack([k.flex_l, k.flex_r])
    plan.arm_abd = np.stack([k.abd_l, k.abd_r])
    plan.elbow = np.stack([k.elbow_l, k.elbow_r])
    plan.feet[:, :, 0] += np.array(_SIDES)[:, None] * 0.05 * m.leg
    plan.pelvis[:, 0] = 0.06 * m.leg * np.sin(k.yaw)
    plan.pelvis[:, 2] = -0.2 * m.leg * np.sin(k.tilt)
    plan.pelvis[:, 1] = _pelvis_height(plan, m.body, np.degrees(k.knee))
    return plan


def _point(m: _Setup) -> _Plan:
    """Pointing 0.35 times a second: each time one arm (left or right at random) rises
    straight to a random direction 0..75° out from the front and 5..40° above the
    horizontal, holds, and lowers again, the chest turning a little toward it."""
    plan = _Plan.rest(m)
    ph = m.cycle(0.35)
    cycle = np.floor(ph).astype(int)
    cycle -= cycle[0]
    count = cycle[-1] + 1
    arm = m.rng.integers(2, size=count)[cycle]
    azimuth = np.radians(m.rng.uniform(0.0, 75.0, count))[cycle]
    elevation = np.radians(m.rng.uniform(5.0, 40.0, count))[cycle]
    u = ph - np.floor(ph)
    up = _smoothstep((u - 0.1) / 0.2) - _smoothstep((u - 0.7) / 0.2)
    outward = np.cos(elevation) * np.sin(azimuth)
    forward = np.cos(elevation) * np.cos(azimuth)
    pointing = np.arange(2)[:, None] == arm  # (2, n)
    # The arm along (outward, up, forward): abduction asin(outward), flexion atan2(forward,
    # -up), inverting `_limb_axes`; both ramp up from rest with `up`.
    rest_abd, rest_elbow = plan.arm_abd[0, 0], plan.elbow[0, 0]
    plan.arm_flex = np.where(pointing, np.arctan2(forward, -np.sin(elevation)) * up, 0.0)
    plan.arm_abd = np.where(pointing, rest_abd + (np.arcsin(outward) - rest_abd) * up, rest_abd)
    plan.elbow = np.where(pointing, rest_elbow + (np.radians(4.0) - rest_elbow) * up, rest_elbow)
    toward = np.array(_SIDES)[arm]
    plan.twist = 0.3 * toward * azimuth * up
    plan.pelvis[:, 0] = -0.02 * toward * up
    plan.roll = np.radians(1.5) * toward * up
    plan.pelvis[:, 1] = _pelvis_height(plan, m.body, 8.0)
    return plan


_BUILDERS: dict[str, Callable[[_Setup], _Plan]] = {
    "walk": partial(_locomotion, run=False),
    "run": partial(_locomotion, run=True),
    "jumping_jacks": _jumping_jacks,
    "arm_swing": _arm_swing,
    "squat": _squat,
    "kick": _kick,
    "wave": _wave,
    "turn": _turn,
    "golf_swing": _golf_swing,
    "point": _point,
}


def _place(poses: np.ndarray, hop: np.ndarray, heading: float, start: np.ndarray) -> np.ndarray:
    """Lift poses (n, 13, 3) so the lower ankle is at `hop` (n,) m, then turn and move them."""
    poses[..., 1] += (hop - poses[:, [11, 12], 1].min(axis=1))[:, None]
    turn = _rot(1, np.array([heading]))[0]
    return poses @ turn.T + np.array([start[0], 0.0, start[1]])


def generate(
    motion: str,
    seconds: float = 4.0,
    fps: float = 30.0,
    seed: int = 0,
    body: Body | None = None,
    speed: float | None = None,
) -> Take:
    """One synthetic take of `motion` (one of `MOTIONS`): round(seconds * fps) poses.

    The poses are (n, 13, 3) float32 meters in the world frame (+Y up, ankles on y = 0
    in ground contact). `body` defaults to `random_body`, `speed` (a factor on the cycle
    frequency and travel speed) to a draw from 0.8..1.25; heading, start position on the
    floor (x, z in -1..1 m) and start phase are random too. Everything derives from
    `seed`, so the same arguments give identical poses and content hash.
    """
    if motion not in _BUILDERS:
        raise ValueError(f"unknown motion {motion!r}; valid motions: {', '.join(MOTIONS)}")
    if not (seconds > 0 and fps > 0 and np.isfinite(seconds * fps)):
        raise ValueError(f"seconds and fps must be positive and finite, got {seconds}, {fps}")
    if speed is not None and not speed > 0:
        raise ValueError(f"speed must be positive, got {speed}")
    seconds, fps = float(seconds), float(fps)
    n = round(seconds * fps)
    if n < 1:
        raise ValueError(f"{seconds} s at {fps} fps gives no frames")
    rng = np.random.default_rng(seed)
    drawn_body, drawn_speed = random_body(rng), rng.uniform(0.8, 1.25)
    heading, start, phase = rng.uniform(0.0, 2 * np.pi), rng.uniform(-1.0, 1.0, 2), rng.uniform()
    body = drawn_body if body is None else body
    speed = drawn_speed if speed is None else float(speed)
    plan = _BUILDERS[motion](_Setup(np.arange(n) / fps, body, speed, phase, rng))
    poses = _place(_forward(plan, body), plan.hop, heading, start)
    source = f"synthetic:{motion}?seed={seed}&seconds={seconds}&fps={fps}"
    digest = hashlib.sha256(f"{source}|speed={speed!r}|body={body!r}".encode()).hexdigest()
    return Take(
        name=f"synthetic-{motion}-{seed}",
        poses=poses,
        fps=fps,
        source=source,
        content_hash=digest,
        rig="synthetic",
        subject=f"synthetic-{seed}",
        action=motion,
    )


def library(
    takes_per_motion: int = 3, seconds: float = 4.0, fps: float = 30.0, seed: int = 0
) -> list[Take]:
    """`takes_per_motion` takes of every motion in `MOTIONS` order, (n, 13, 3) poses each.

    Take number `index` of the library (counted over all motions) uses the seed
    `seed * 1000 + index`, so every take has its own body, speed, heading and start.
    """
    if takes_per_motion < 0:
        raise ValueError(f"takes_per_motion must be >= 0, got {takes_per_motion}")
    return [
        generate(motion, seconds, fps, seed * 1000 + m * takes_per_motion + i)
        for m, motion in enumerate(MOTIONS)
        for i in range(takes_per_motion)
    ]
