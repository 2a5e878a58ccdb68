"""The pose-store tests' takes and stores: distinct synthetic poses, takes of them, a
store of three takes, and the bytes of a store's files."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from samba.body.perturb import perturb_joint_angles
from samba.body.skeleton import Body
from samba.body.take import Take


def make_poses(n: int, seed: int) -> np.ndarray:
    """n distinct float32 poses (meters): perturbed A-poses of one body drifting on the floor."""
    rng = np.random.default_rng(seed)
    body = Body.from_height(float(rng.uniform(1.5, 1.9)))
    base = np.broadcast_to(body.standard_pose(float(rng.uniform(20, 70))), (n, 13, 3))
    poses = perturb_joint_angles(base, 15.0, rng)
    poses += np.cumsum(rng.normal(0, 0.01, (n, 1, 3)), axis=0) * [1.0, 0.0, 1.0]
    return poses.astype(np.float32)


def make_take(name: str, n: int = 30, seed: int = 0, **fields: object) -> Take:
    """A take of n poses whose content (and content hash) is set by `seed`."""
    defaults: dict[str, object] = {
        "fps": 30.0,
        "source": f"test://{name}",
        "content_hash": f"hash-{seed}",
        "rig": "test",
    }
    defaults.update(fields)
    return Take(name=name, poses=make_poses(n, seed), **defaults)  # type: ignore[arg-type]


def snapshot_files(path: Path) -> dict[str, bytes]:
    """Every file of a store directory (but the lock file) with its bytes."""
    return {p.name: p.read_bytes() for p in sorted(path.iterdir()) if p.name != "lock"}


def data_files(path: Path) -> set[str]:
    """Names of the pose and row data files in a store directory."""
    return {p.name for p in path.iterdir() if p.name.startswith(("poses-", "rows-"))}
