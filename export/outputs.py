"""Where and how `samba export` writes takes: the format an output name implies, each
take's output file, the avatar the takes are put on, and the writer of each format
(USD, glTF binary, BVH), each loaded only when a take is written in its format."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from samba.export.avatar_mesh import AvatarMesh
from samba.export.errors import ExportError
from samba.export.humanoid import HumanoidRig
from samba.export.motion import HumanoidMotion

FORMAT_SUFFIXES: dict[str, tuple[str, ...]] = {
    "usd": (".usda", ".usdc", ".usd", ".usdz"),
    "glb": (".glb",),
    "bvh": (".bvh",),
}
"""Format -> accepted output suffixes; the first is used for files named in a folder."""


@dataclass(frozen=True)
class Avatar:
    """What the takes are put on: the rig and, for USD and glTF, its skinned mesh."""

    rig: HumanoidRig
    mesh: AvatarMesh


def format_of(path: Path) -> str:
    """The export format an output file's suffix implies; `ExportError` if none does."""
    for fmt, suffixes in FORMAT_SUFFIXES.items():
        if path.suffix.lower() in suffixes:
            return fmt
    raise ExportError(
        str(path),
        "cannot tell the format from the suffix: give --format "
        "usd|glb|bvh or name the file .usda, .usdc, .usd, .usdz, .glb or .bvh",
    )


def output_paths(
    takes: list[str], fmt: str, output: Path | None, out_dir: Path | None
) -> list[tuple[str, Path]]:
    """Each take with the file it goes to: `output` (`-o`) for one take, else
    `out_dir`/<take name><suffix> (`--out-dir`, created when missing). `ExportError`
    naming the flag when several takes would go to one file or to the same name, when
    `output` is a folder or has another format's suffix, or `out_dir` is a file."""
    if output is not None:
        if len(takes) > 1:
            raise ExportError(
                "--output", f"{len(takes)} takes cannot go to one file; give --out-dir DIR"
            )
        if output.is_dir():
            raise ExportError(str(output), "is a folder; give --out-dir to write into it")
        if output.suffix.lower() not in FORMAT_SUFFIXES[fmt]:
            raise ExportError(
                str(output), f"a {fmt} file must end in {' or '.join(FORMAT_SUFFIXES[fmt])}"
            )
        return [(takes[0], output)]
    assert out_dir is not None
    if out_dir.exists() and not out_dir.is_dir():
        raise ExportError(str(out_dir), "--out-dir names a file; give a folder")
    suffix = FORMAT_SUFFIXES[fmt][0]
    paths = [(ref, out_dir / f"{Path(ref).stem}{suffix}") for ref in takes]
    names = [p for _, p in paths]
    if len(set(names)) != len(names):
        twice = next(p for p in names if names.count(p) > 1)
        raise ExportError(str(twice), "two takes would be written to this one file")
    return paths


def load_avatar(path: str | None) -> Avatar:
    """The avatar of `--avatar FILE`, or the default mannequin; a generated, skinned
    mannequin body in both cases."""
    from samba.export.mannequin import mannequin

    if path is None:
        rig = HumanoidRig.from_body()
    else:
        from samba.export.avatar_file import read_avatar_rig

        rig = read_avatar_rig(path)
    return Avatar(rig=rig, mesh=mannequin(rig))


def write_export(fmt: str, path: Path, motion: HumanoidMotion, mesh: AvatarMesh, unit: str) -> None:
    """Write `motion` to `path` in `fmt` (USD and glTF with the skinned `mesh`, BVH in
    `unit`)."""
    if fmt == "bvh":
        from samba.export.bvh_writer import write_bvh  # each writer loads only when used

        write_bvh(path, motion, unit=unit)
    elif fmt == "glb":
        from samba.export.gltf_writer import write_glb

        write_glb(path, motion, mesh)
    else:
        from samba.export.usd_writer import write_usd  # loads pxr (USD), 0.3 s

        write_usd(path, motion, mesh)
