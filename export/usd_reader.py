"""Reading USD files: joint world positions posed by UsdSkel itself and the UsdValidation
report, to verify what `samba.export.usd_writer` writes (FORMATS.md §1.6, §1.7), and the rest
pose of every UsdSkel Skeleton, in our frame, for avatars (`samba.export.avatar_file`)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pxr import Tf, Usd, UsdGeom, UsdSkel, UsdValidation

from samba.export.errors import ExportError
from samba.export.usd_writer import tf_error_text

_Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""Rotation (-90 degrees about X) taking a Z-up stage's points to +Y up: (x, y, z) ->
(x, z, -y)."""


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
    stage = _open(path)  # the prims live as long as their stage: keep it
    skeleton = _skeletons(stage, path)[0]
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
    return _leaf_names(query.GetJointOrder()), positions


@dataclass(frozen=True)
class SkeletonRest:
    """A UsdSkel Skeleton's rest pose: its prim `path`, the leaf `names` of its joint
    tokens (the last path component, in joint order) and the joints' world `positions`
    (n_joints, 3) in meters, right-handed, +Y up, and their `parents`; or, for a Skeleton
    that cannot be posed, the `problem` (one line naming it) and no positions (0, 3)."""

    path: str
    names: tuple[str, ...]
    positions: np.ndarray
    problem: str | None = None
    parents: tuple[int, ...] = ()
    """Each joint's parent joint (-1 for a root), from the joint tokens' paths."""


def read_usd_skeleton_rests(path: str | os.PathLike[str]) -> list[SkeletonRest]:
    """The rest pose of every UsdSkel Skeleton in a USD file, in stage traversal order.

    A joint's world rest transform is its `restTransforms` (local) concatenated down the
    joint hierarchy and placed by the Skeleton prim's own world transform (at the earliest
    time), or, without `restTransforms`, its `bindTransforms` (world space by UsdSkel's
    definition). Positions are converted from the stage's `metersPerUnit` to meters and
    from a Z-up stage to +Y up (x, y, z -> x, z, -y: a model facing -Y faces +Z). A
    Skeleton whose joints are mis-ordered or have neither transform array for every
    joint comes with its `problem`. Raises `ExportError` naming the file when it cannot
    be read or has no Skeleton.
    """
    stage = _open(path)
    scale = UsdGeom.GetStageMetersPerUnit(stage)
    to_y_up = _Z_UP_TO_Y_UP if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z else np.eye(3)
    rests = []
    for skeleton in _skeletons(stage, path):
        tokens = skeleton.GetJointsAttr().Get() or []
        where, names = str(skeleton.GetPath()), _leaf_names(tokens)
        try:
            world = _world_rest_transforms(skeleton, tokens, str(path))
        except ExportError as exc:
            rests.append(SkeletonRest(where, names, np.zeros((0, 3)), exc.problem))
            continue
        parents = tuple(int(p) for p in UsdSkel.Topology(tokens).GetParentIndices())
        positions = scale * world[:, 3, :3] @ to_y_up.T
        rests.append(SkeletonRest(where, names, positions, parents=parents))
    return rests


def _leaf_names(tokens: Sequence[str]) -> tuple[str, ...]:
    """The last path component of each joint token ("Hips/Spine" -> "Spine")."""
    return tuple(str(token).rsplit("/", 1)[-1] for token in tokens)


def _world_rest_transforms(
    skeleton: UsdSkel.Skeleton, tokens: Sequence[str], source: str
) -> np.ndarray:
    """World rest matrices (n_joints, 4, 4) of a Skeleton, USD row-vector layout (the
    translation in row 3), in stage units."""
    where = f"skeleton {skeleton.GetPath()}"
    if not tokens:
        raise ExportError(source, f"{where} has no joints")
    topology = UsdSkel.Topology(tokens)
    valid, why = topology.Validate()
    if not valid:
        raise ExportError(source, f"{where}: {why}")
    rest = skeleton.GetRestTransformsAttr().Get()
    if rest is not None and len(rest) == len(tokens):
        placed = UsdGeom.Xformable(skeleton).ComputeLocalToWorldTransform(
            Usd.TimeCode.EarliestTime()
        )
        return np.asarray(UsdSkel.ConcatJointTransforms(topology, rest)) @ np.asarray(placed)
    bind = skeleton.GetBindTransformsAttr().Get()
    if bind is not None and len(bind) == len(tokens):
        return np.asarray(bind)
    raise ExportError(
        source, f"{where} has no restTransforms or bindTransforms for its {len(tokens)} joints"
    )


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


def _skeletons(stage: Usd.Stage, path: str | os.PathLike[str]) -> list[UsdSkel.Skeleton]:
    """Every Skeleton prim of `stage` in traversal order; `ExportError` naming `path` when
    there is none."""
    skeletons = [UsdSkel.Skeleton(prim) for prim in stage.Traverse() if prim.IsA(UsdSkel.Skeleton)]
    if not skeletons:
        raise ExportError(str(path), "no UsdSkel Skeleton prim in the file")
    return skeletons


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
