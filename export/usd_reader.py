"""Reading USD exports back: joint world positions posed by UsdSkel itself, and the
UsdValidation report. Used to verify what `export.usd_writer` writes (FORMATS.md §1.6, §1.7)."""

from __future__ import annotations

import os

import numpy as np
from pxr import Tf, Usd, UsdGeom, UsdSkel, UsdValidation

from export.errors import ExportError
from export.usd_writer import tf_error_text


def read_usd_joint_positions(
    path: str | os.PathLike[str],
) -> tuple[tuple[str, ...], np.ndarray]:
    """Joint names and world positions of the first skeleton in a USD file.

    Returns the leaf names of the skeleton's joint tokens (in its joint order) and their
    positions (n_frames, n_joints, 3) in stage units, one frame per time sample of the
    skeleton's animation (a single frame at the default time when it has none: the rest
    pose for a skeleton without animation), posed by UsdSkel. Raises `ExportError` naming
    the file when it cannot be read or holds no valid skeleton under a SkelRoot.
    """
    stage = _open(path)
    skeleton = next(
        (UsdSkel.Skeleton(prim) for prim in stage.Traverse() if prim.IsA(UsdSkel.Skeleton)), None
    )
    if skeleton is None:
        raise ExportError(str(path), "no UsdSkel Skeleton in the file")
    root = UsdSkel.Root.Find(skeleton.GetPrim())
    if not root:
        raise ExportError(str(path), f"skeleton {skeleton.GetPath()} is not under a SkelRoot")
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.PrimDefaultPredicate)
    query = cache.GetSkelQuery(skeleton)
    if not query or not query.GetJointOrder():
        raise ExportError(str(path), f"skeleton {skeleton.GetPath()} is invalid or has no joints")
    animation = query.GetAnimQuery()
    times = animation.GetJointTransformTimeSamples() if animation else []
    times = times or [Usd.TimeCode.Default()]
    positions = np.empty((len(times), len(query.GetJointOrder()), 3))
    for frame, time in enumerate(times):
        # the time comes from the XformCache: a second argument would be `atRest`
        world = query.ComputeJointWorldTransforms(UsdGeom.XformCache(time))
        if len(world) != positions.shape[1]:
            raise ExportError(str(path), f"UsdSkel cannot pose {skeleton.GetPath()} at {time}")
        positions[frame] = np.asarray(world)[:, 3, :3]
    names = tuple(str(token).rsplit("/", 1)[-1] for token in query.GetJointOrder())
    return names, positions


def usd_validation_errors(path: str | os.PathLike[str]) -> list[str]:
    """Every issue UsdValidation's registered validators find in a USD file, as
    "<error name>: <message>" lines (empty for a clean file). Raises `ExportError`
    naming the file when it cannot be read."""
    stage = _open(path)
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    return [
        f"{issue.GetName()}: {issue.GetMessage()}"
        for issue in context.Validate(stage)
        if not issue.HasNoError()
    ]


def _open(path: str | os.PathLike[str]) -> Usd.Stage:
    """The stage of a USD file, or `ExportError` naming it."""
    if not os.path.isfile(path):
        raise ExportError(str(path), "cannot read the file: no such file")
    try:
        stage = Usd.Stage.Open(os.fspath(path), Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:
        raise ExportError(str(path), f"cannot read the file as USD: {tf_error_text(exc)}") from exc
    if stage is None:
        raise ExportError(str(path), "cannot read the file as USD")
    return stage
