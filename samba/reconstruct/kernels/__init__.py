"""Compiled kernels of the reconstruction's per-frame path (numba, `@njit(cache=True)`).

`local_solutions_kernel` computes, frame by frame in one compiled loop, what
`Reconstructor._solve_batch` computes with numpy (its reference, kept and selected by
`SAMBA_KERNELS=numpy`): from the observed markers and their K neighbour poses, the
alignment of both into the canonical frame (`samba.body.Alignment`), the pseudo-poses
(`pseudo_poses`), the samples' kernel weights (`Reconstructor.sample_weights`), the local
pose space (`LocalPoseSpace.from_samples`), the energy's affine minimiser
(`affine_solution`) and its turn back to the world frame. `part_estimates_kernel` does
the same for `part_retrieval.neighbour_mean` after its index query (the neighbours aligned
by the part's markers, their kernel-weighted mean, turned back), and
`part_regressions_kernel` for `local_regression.local_regression_numpy` (the same neighbours'
locally weighted linear regression, read at the observation). The numpy functions stay
the references; `tests/test_reconstruct_kernels.py` checks that both paths give the same
poses (1e-9 m).

The reconstruction takes the kernel unless `samba.base.kernels_enabled()` says no
(`SAMBA_KERNELS=numpy`, for debugging, or no numba on the platform). Numba compiles it on
its first call and caches the machine code beside this module (`__pycache__`), so only the
first run after an install pays the compile: `KERNELS.warm_up()` (called by every
`Reconstructor`, and by `samba warmup`) says so on that run.
"""

from __future__ import annotations

import numpy as np

from samba.base import KernelSet
from samba.body import MARKER_JOINTS, N_JOINTS, standard_pose
from samba.reconstruct.kernels.frames import local_poses_kernel, local_solutions_kernel
from samba.reconstruct.kernels.parts import part_estimates_kernel, part_regressions_kernel

_DIMS = 3 * N_JOINTS

__all__ = [
    "KERNELS",
    "local_poses_kernel",
    "local_solutions_kernel",
    "part_estimates_kernel",
    "part_regressions_kernel",
]


def _example() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compile `local_solutions_kernel` for the reconstruction's argument types."""
    pose = standard_pose()
    markers = np.ascontiguousarray(pose[list(MARKER_JOINTS)][None])
    neighbours = np.ascontiguousarray(np.repeat(pose[None, None], 2, axis=1))
    settings = np.array([0.9, 1e-6, 1e-12, 1e-12, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0])
    arguments = (np.ones(1, dtype=np.bool_), np.zeros((2, 5, 2, 21)), False, settings)
    local_poses_kernel(markers, neighbours, np.zeros((1, _DIMS)), *arguments)
    return local_solutions_kernel(markers, neighbours, *arguments)


def _example_parts() -> np.ndarray:
    """Compile `part_estimates_kernel` for the reconstruction's argument types."""
    pose = standard_pose()
    markers = np.ascontiguousarray(pose[list(MARKER_JOINTS)][None])
    neighbours = np.ascontiguousarray(np.repeat(pose[None, None], 2, axis=1))
    return part_estimates_kernel(markers, neighbours, np.zeros((1, 2)), False)


def _example_regressions() -> np.ndarray:
    """Compile `part_regressions_kernel` for the reconstruction's argument types."""
    pose = standard_pose()
    markers = np.ascontiguousarray(pose[list(MARKER_JOINTS)][None])
    neighbours = np.ascontiguousarray(np.repeat(pose[None, None], 2, axis=1))
    joints = np.zeros((1, 1), dtype=np.int64)
    return part_regressions_kernel(markers, neighbours, np.zeros((1, 2)), joints, False, 1.0, 2.0)


KERNELS = KernelSet(
    "reconstruction",
    (local_solutions_kernel, local_poses_kernel, part_estimates_kernel, part_regressions_kernel),
    (_example, _example_parts, _example_regressions),
    estimate_s=20.0,
)
"""The reconstruction's kernels, warmed by every `Reconstructor` (`KernelSet.warm_up`)."""
