"""USD export (.usda text, .usdc or .usd binary, .usdz package): the humanoid skeleton, its
animation, an optional skinned body, as UsdSkel (FORMATS.md §1).

Layout (§1.1), which UsdValidation passes with no errors:

* `/Avatar` SkelRoot, the stage's default prim, no transform;
* `/Avatar/Skel` Skeleton with SkelBindingAPI and `skel:animationSource` ->
  `/Avatar/Skel/Anim`; its joints are path-like tokens ("Hips/Spine/Chest/Neck") in bone
  order, `jointNames` the plain Unity / VRM humanoid names, `bindTransforms` the world rest
  matrices and `restTransforms` the local ones (translation = rest offset from the parent,
  Hips: its rest position; every rest rotation is the identity);
* `/Avatar/Skel/Anim` SkelAnimation: local translations (the rest offsets, Hips the
  motion's root), rotations and unit scales, all three sampled at every frame;
* with a mesh, `/Avatar/Body` Mesh bound to the skeleton: rest-pose points in skeleton
  space (identity `geomBindTransform`), vertex normals, 4 joint indices and weights per
  vertex.

Stage metadata: +Y up, 1 meter per unit, time codes are frame numbers 0 .. n - 1 at
`motion.fps` per second. Our frame is USD's, so no axis change is needed.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, UsdUtils, Vt

from samba.base import atomic_path
from samba.export.avatar_mesh import MAX_INFLUENCES, AvatarMesh
from samba.export.errors import ExportError
from samba.export.humanoid import HumanoidRig
from samba.export.motion import HumanoidMotion

SUFFIXES: tuple[str, ...] = (".usda", ".usdc", ".usd", ".usdz")
"""File name suffixes `write_usd` accepts (any letter case): the suffix picks text (.usda),
binary (.usdc; .usd is binary too, USD's default for it) or a USDZ package (.usdz: the
binary layer zipped as Apple's AR tools and asset stores take it)."""
ROOT_PATH = Sdf.Path("/Avatar")
SKELETON_PATH = ROOT_PATH.AppendChild("Skel")
ANIMATION_PATH = SKELETON_PATH.AppendChild("Anim")
BODY_PATH = ROOT_PATH.AppendChild("Body")


def write_usd(
    path: str | os.PathLike[str], motion: HumanoidMotion, mesh: AvatarMesh | None = None
) -> None:
    """Write `motion` (and `mesh` skinned to its rig, if given) as USD at `path`: text for
    a `.usda` suffix, binary for `.usdc` or `.usd`, a USDZ package for `.usdz` (made by
    usd-core's ARKit packaging, `UsdUtils.CreateNewARKitUsdzPackage`).

    Lengths in meters, one time code per frame (frame k at k / motion.fps seconds). The
    stage is built in memory and exported atomically: on any failure `path` keeps its old
    content (or stays absent). Raises `ExportError` naming `path` for another suffix or
    when it cannot be written, `ValueError` for a mesh without triangles.
    """
    suffix = Path(path).suffix
    if suffix.lower() not in SUFFIXES:
        raise ExportError(
            str(path), f"unsupported file type {suffix!r}: use .usda, .usdc, .usd or .usdz"
        )
    stage = _stage(motion, mesh)  # the stage owns the layer: keep it alive while exporting
    try:
        with atomic_path(path) as tmp:
            if suffix.lower() == ".usdz":
                _package(stage, Path(path).stem, tmp)
            elif not stage.GetRootLayer().Export(str(tmp)):
                raise OSError(f"USD could not export to {tmp}")
    except Tf.ErrorException as exc:
        raise ExportError(str(path), f"cannot write the file: {tf_error_text(exc)}") from exc
    except OSError as exc:
        raise ExportError(str(path), f"cannot write the file: {exc.strerror or exc}") from exc


def _package(stage: Usd.Stage, name: str, usdz: Path) -> None:
    """Write `stage` as the USDZ package `usdz`: its layer exported as `name`.usdc in a
    temporary folder, then packaged by usd-core for ARKit."""
    with tempfile.TemporaryDirectory(prefix="samba-usdz-") as folder:
        layer = Path(folder) / f"{name}.usdc"
        if not stage.GetRootLayer().Export(str(layer)):
            raise OSError(f"USD could not export to {layer}")
        if not UsdUtils.CreateNewARKitUsdzPackage(Sdf.AssetPath(str(layer)), str(usdz)):
            raise OSError(f"USD could not package {layer} as {usdz}")


def tf_error_text(exc: Tf.ErrorException) -> str:
    """The distinct messages of the USD errors an exception carries, joined by "; " (the
    exception's own text repeats each with its C++ source location)."""
    messages = [getattr(error, "commentary", str(error)) for error in exc.args]
    return "; ".join(dict.fromkeys(messages))


def joint_tokens(rig: HumanoidRig) -> list[str]:
    """The rig's UsdSkel joint tokens in bone order: each bone's name prefixed by its
    ancestors' ("Hips/Spine/Chest/LeftUpperArm")."""
    tokens: list[str] = []
    for name, parent in zip(rig.names, rig.parents, strict=True):
        tokens.append(name if parent < 0 else f"{tokens[parent]}/{name}")
    return tokens


def _stage(motion: HumanoidMotion, mesh: AvatarMesh | None) -> Usd.Stage:
    """An in-memory stage holding the whole export."""
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, UsdGeom.LinearUnits.meters)
    stage.SetTimeCodesPerSecond(motion.fps)
    stage.SetFramesPerSecond(motion.fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(len(motion) - 1)
    root = UsdSkel.Root.Define(stage, ROOT_PATH)
    stage.SetDefaultPrim(root.GetPrim())
    _skeleton(stage, motion.rig)
    _animation(stage, motion)
    if mesh is not None:
        _body(stage, mesh)
    return stage


def _skeleton(stage: Usd.Stage, rig: HumanoidRig) -> None:
    """The Skeleton prim: joints, names, world bind and local rest matrices."""
    skeleton = UsdSkel.Skeleton.Define(stage, SKELETON_PATH)
    skeleton.CreateJointsAttr(Vt.TokenArray(joint_tokens(rig)))
    skeleton.CreateJointNamesAttr(Vt.TokenArray(list(rig.names)))
    skeleton.CreateBindTransformsAttr(_translation_matrices(rig.rest))
    skeleton.CreateRestTransformsAttr(_translation_matrices(rig.offsets))
    binding = UsdSkel.BindingAPI.Apply(skeleton.GetPrim())
    binding.CreateAnimationSourceRel().SetTargets([ANIMATION_PATH])


def _translation_matrices(translations: np.ndarray) -> Vt.Matrix4dArray:
    """USD matrices (row vectors: translation in the last row) of translations (J, 3)."""
    matrices = np.tile(np.eye(4), (len(translations), 1, 1))
    matrices[:, 3, :3] = translations
    return Vt.Matrix4dArray.FromNumpy(matrices)


def _animation(stage: Usd.Stage, motion: HumanoidMotion) -> None:
    """The SkelAnimation prim: translations, rotations and scales at every frame."""
    animation = UsdSkel.Animation.Define(stage, ANIMATION_PATH)
    animation.CreateJointsAttr(Vt.TokenArray(joint_tokens(motion.rig)))
    translations = np.repeat(motion.rig.offsets[None].astype(np.float32), len(motion), axis=0)
    translations[:, 0] = motion.root
    # GfQuatf lays out (x, y, z) then w in memory, our own order: FromNumpy copies the
    # bytes, so the rows need no reordering (unlike the Gf.Quatf(w, x, y, z) constructor)
    rotations = np.ascontiguousarray(motion.rotations, dtype=np.float32)
    scales = Vt.Vec3hArray.FromNumpy(np.ones(translations.shape[1:], dtype=np.float16))
    paths = [
        attr.GetPath()
        for attr in (
            animation.CreateTranslationsAttr(),
            animation.CreateRotationsAttr(),
            animation.CreateScalesAttr(),
        )
    ]
    layer = stage.GetRootLayer()
    with Sdf.ChangeBlock():  # Sdf-level edits only inside: Usd would see a stale stage
        for frame in range(len(motion)):
            layer.SetTimeSample(paths[0], frame, Vt.Vec3fArray.FromNumpy(translations[frame]))
            layer.SetTimeSample(paths[1], frame, Vt.QuatfArray.FromNumpy(rotations[frame]))
            layer.SetTimeSample(paths[2], frame, scales)


def _body(stage: Usd.Stage, mesh: AvatarMesh) -> None:
    """The Mesh prim skinned to the skeleton, in the rest pose."""
    if len(mesh.faces) == 0:
        raise ValueError("avatar mesh has no triangles")
    body = UsdGeom.Mesh.Define(stage, BODY_PATH)
    body.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    body.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(mesh.vertices))
    body.CreateExtentAttr(
        Vt.Vec3fArray.FromNumpy(np.stack([mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)]))
    )
    body.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(mesh.normals))
    body.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    body.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(mesh.faces), 3, np.int32)))
    body.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(mesh.faces.reshape(-1).astype(np.int32)))
    binding = UsdSkel.BindingAPI.Apply(body.GetPrim())
    binding.CreateSkeletonRel().SetTargets([SKELETON_PATH])
    binding.CreateJointIndicesPrimvar(False, MAX_INFLUENCES).Set(
        Vt.IntArray.FromNumpy(mesh.joints.reshape(-1).astype(np.int32))
    )
    binding.CreateJointWeightsPrimvar(False, MAX_INFLUENCES).Set(
        Vt.FloatArray.FromNumpy(mesh.weights.reshape(-1))
    )
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
