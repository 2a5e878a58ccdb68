"""A plain numpy reference of the Samba paper's reconstruction, run on the protocol of
`samba eval` (issue 44): the yardstick `samba` must not lose to.

Written apart from `samba.reconstruct` (it shares only the capture of
`samba.evaluation.protocol`, the BVH reader and `markers_of`), in the paper's terms:

- the observation and every database pose are placed by their shoulder midpoint, turned
  about +Y so the shoulder line runs along +X (knees, feet or wrists when a shoulder is
  lost, and then the markers' centroid as origin);
- K = 10 nearest poses by brute force over those placed markers (the markers present);
- N = 10 pseudo-poses each: 5-degree Gaussian angles, elbows and knees about the limb
  plane's normal, shoulders, hips and the neck swung about the two axes across the bone;
- the local PCA of the K * N samples keeping 99.9% of the variance, and the energy
  prior + marker (sigma 5 mm) + smoothness (sigma 8 cm) minimised exactly in it;
- a missing marker held where it was last seen (the paper's tracker).

    python bench/samba_reference.py [CMU_DIR] [--dropout 0.1] [--new-user] [--every S]
                                    [--max-frames F]

Leave-one-take-out over CMU_DIR (default ../shared/data/cmu), every S-th take tested;
prints the rows of issue 44 (cm at a 45 cm tibia) for `nn` (the nearest pose, placed)
and `samba`.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from samba.body import markers_of
from samba.evaluation.protocol import capture_take, tibia_scale
from samba.ingest import load_bvh_take

K, N, NOISE_DEG, KEPT, MARKER_SIGMA, SMOOTH_SIGMA = 10, 10, 5.0, 0.999, 0.005, 0.08
MARKER_JOINTS = [1, 2, 5, 6, 9, 10, 11, 12]
MARKER_COORDS = [3 * j + c for j in MARKER_JOINTS for c in range(3)]
PAIRS = [(0, 1), (4, 5), (6, 7), (2, 3)]  # marker pairs for the heading, in order
CHAINS = [(None, 0, 0), (1, 3, 5), (2, 4, 6), (7, 9, 11), (8, 10, 12)]  # root, mid, end
ROWS = {
    "all 13 joints": list(range(13)),
    "8 marker joints": MARKER_JOINTS,
    "5 unobserved": [0, 3, 4, 7, 8],
    "head": [0],
    "elbows (mean of both)": [3, 4],
    "hips": [7, 8],
}


def placement(markers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origins (n, 3) and world-to-canonical rotations (n, 3, 3) of marker sets (n, 8, 3)."""
    present = ~np.isnan(markers).any(axis=-1)
    origin = np.nanmean(np.where(present[..., None], markers, np.nan), axis=1)
    both = present[:, 0] & present[:, 1]
    origin[both] = markers[both, :2].mean(axis=1)
    line = np.zeros((len(markers), 3))
    found = np.zeros(len(markers), dtype=bool)
    for left, right in PAIRS:
        use = ~found & present[:, left] & present[:, right]
        line[use] = markers[use, left] - markers[use, right]
        found |= use
    yaw = np.arctan2(line[:, 2], line[:, 0])
    return origin, Rotation.from_rotvec(np.outer(yaw, [0.0, 1.0, 0.0])).as_matrix()


def place(points: np.ndarray, origin: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Points (n, m, 3) to the canonical frame."""
    return np.einsum("nij,nmj->nmi", rotation, points - origin[:, None])


def nearest(database: np.ndarray, markers: np.ndarray, k: int) -> np.ndarray:
    """Rows (F, k) of the k database poses nearest to each observation, by placed markers."""
    present = ~np.isnan(markers).any(axis=-1)
    seen = place(markers, *placement(markers))
    db_markers = markers_of(database)
    rows = np.empty((len(markers), k), dtype=np.int64)
    for mask in np.unique(present, axis=0):
        frames = np.flatnonzero((present == mask).all(axis=1))
        masked = np.where(mask[None, :, None], db_markers, np.nan)
        table = place(masked, *placement(masked))[:, mask].reshape(len(database), -1)
        query = seen[frames][:, mask].reshape(len(frames), -1)
        d2 = (table**2).sum(1)[None] - 2.0 * query @ table.T
        rows[frames] = np.argsort(d2, axis=1)[:, :k]
    return rows


def rotate_about(points: np.ndarray, centre: np.ndarray, axis: np.ndarray, angle: np.ndarray):
    """Points (..., 3) rotated by angle (...) about unit axis (..., 3) through centre."""
    matrices = Rotation.from_rotvec((axis * angle[..., None]).reshape(-1, 3)).as_matrix()
    moved = np.einsum("nij,nj->ni", matrices, (points - centre).reshape(-1, 3))
    return moved.reshape(points.shape) + centre


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def pseudo_poses(poses: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Poses (F, K, 13, 3) -> (F, K, N, 13, 3) with the joint angles (K, N, 5, 3) radians:
    per chain a hinge angle (none for the neck) and two swing angles."""
    out = np.repeat(poses[:, :, None], angles.shape[1], axis=2)
    shoulder_line = out[..., 1, :] - out[..., 2, :]
    for chain, (root, mid, end) in enumerate(CHAINS):
        a = np.broadcast_to(angles[None, :, :, chain], (*out.shape[:3], 3))
        centre = out[..., 1:3, :].mean(axis=-2) if root is None else out[..., root, :]
        if root is not None:  # the hinge, about the normal of the limb plane
            normal = unit(np.cross(out[..., mid, :] - centre, out[..., end, :] - out[..., mid, :]))
            out[..., end, :] = rotate_about(out[..., end, :], out[..., mid, :], normal, a[..., 0])
        z = unit(out[..., mid, :] - centre)
        x = unit(shoulder_line - (shoulder_line * z).sum(-1, keepdims=True) * z)
        moved = [mid] if mid == end else [mid, end]
        for axis, angle in ((np.cross(z, x), a[..., 1]), (z, a[..., 2])):
            for joint in moved:
                out[..., joint, :] = rotate_about(out[..., joint, :], centre, axis, angle)
    return out


def reconstruct(database: np.ndarray, markers: np.ndarray, angles: np.ndarray) -> tuple:
    """(nn poses, samba poses), each (F, 13, 3) world meters, of markers (F, 8, 3)."""
    frames = len(markers)
    origin, rotation = placement(markers)
    seen = place(markers, origin, rotation)
    present = ~np.isnan(markers).any(axis=-1)
    neighbours = database[nearest(database, markers, K)].astype(np.float64)  # (F, K, 13, 3)
    masked = np.where(present[:, None, :, None], markers_of(neighbours), np.nan)
    placed = place(neighbours.reshape(-1, 13, 3), *placement(masked.reshape(-1, 8, 3))).reshape(
        neighbours.shape
    )
    back = rotation.transpose(0, 2, 1)
    nn = np.einsum("nij,nmj->nmi", back, placed[:, 0]) + origin[:, None]
    samples = pseudo_poses(placed, angles).reshape(frames, K * N, 39)
    mean = samples.mean(axis=1)
    covariance = np.einsum("fmi,fmj->fij", samples - mean[:, None], samples - mean[:, None])
    variances, bases = np.linalg.eigh(covariance / (K * N))
    coords = np.zeros((frames, 39), dtype=bool)  # the coordinates of the markers present
    coords[:, MARKER_COORDS] = np.repeat(present, 3, axis=1)
    observed = np.zeros((frames, 39))
    observed[:, MARKER_COORDS] = np.nan_to_num(seen).reshape(frames, 24)
    poses = np.empty((frames, 13, 3))
    alpha, beta = MARKER_SIGMA**-2, SMOOTH_SIGMA**-2
    for f in range(frames):
        order = np.argsort(variances[f])[::-1]
        share = np.cumsum(variances[f][order]) / variances[f].sum()
        keep = order[: np.searchsorted(share, KEPT) + 1]
        u, lam = bases[f][:, keep], np.maximum(variances[f][keep], 1e-12)
        us = u[coords[f]]
        lhs = np.diag(1.0 / lam) + alpha * us.T @ us
        rhs = alpha * us.T @ (observed[f, coords[f]] - mean[f, coords[f]])
        if f >= 2:  # the smoothness target 2 q_{i-1} - q_{i-2}, in this frame's canonical frame
            target = place(
                (2.0 * poses[f - 1] - poses[f - 2])[None], origin[f : f + 1], rotation[f : f + 1]
            )
            lhs += beta * np.eye(len(keep))
            rhs += beta * u.T @ (target.reshape(39) - mean[f])
        q = (mean[f] + u @ np.linalg.solve(lhs, rhs)).reshape(13, 3)
        poses[f] = q @ rotation[f] + origin[f]
    return nn, poses


def held(markers: np.ndarray) -> np.ndarray:
    """Markers (F, 8, 3) with each missing marker at its last observed position."""
    out = markers.copy()
    for f in range(1, len(out)):
        lost = np.isnan(out[f]).any(axis=-1)
        out[f, lost] = out[f - 1, lost]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", nargs="?", default=Path(__file__).parents[2] / "shared/data/cmu")
    parser.add_argument("--dropout", type=float, default=0.0)
    parser.add_argument("--new-user", action="store_true")
    parser.add_argument("--every", type=int, default=1)
    parser.add_argument("--max-frames", type=int, default=None)
    args = parser.parse_args()
    files = sorted(Path(args.data).glob("*.bvh"))
    takes = {f.stem: load_bvh_take(f).poses for f in files}
    angles = np.random.default_rng(0).normal(0.0, np.radians(NOISE_DEG), (K, N, 5, 3))
    angles[:, 0] = 0.0  # each neighbour is among its own samples
    errors: dict[str, list[np.ndarray]] = {"nn": [], "samba": []}
    start = time.perf_counter()
    for number, name in enumerate(takes):
        if number % args.every:
            continue
        database = np.concatenate([p for other, p in takes.items() if other != name])
        take = capture_take(
            name, takes[name][: args.max_frames], number, args.dropout, args.new_user
        )
        scale = tibia_scale(take.truth) * 100.0
        for label, poses in zip(
            errors, reconstruct(database, held(take.markers), angles), strict=True
        ):
            errors[label].append(np.linalg.norm(poses - take.truth, axis=-1) * scale)
    seconds = time.perf_counter() - start
    tested = len(errors["samba"])
    print(
        f"reference, leave-one-take-out: {tested} takes, dropout {args.dropout:g}, "
        f"new user {args.new_user}; {seconds:.0f} s"
    )
    print(f"{'cm at tibia 45 cm':24s} {'nn':>6s} {'samba':>6s}")
    for row, joints in ROWS.items():
        cells = [np.concatenate(e)[:, joints].mean() for e in errors.values()]
        print(f"{row:24s} " + " ".join(f"{c:6.2f}" for c in cells))


if __name__ == "__main__":
    main()
