"""`samba reconstruct`: real marker takes (C3D, recorded takes) into 13-joint takes that
other tools open, with every frame posed, and one-line errors for bad input."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from samba.cli import main
from samba.ingest import (
    read_bvh,
    read_c3d,
    read_recorded_markers,
    read_take,
    reference_joints,
)
from samba.reconstruct import SkinOffsets, method
from samba.service.marker_reconstruction import reconstruct_marker_take
from samba.service.session_indexes import SessionIndexes

UP = np.array([0.0, 1.0, 0.0])


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """`samba argv...` in-process: (exit status, stdout, stderr)."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_a_c3d_take_becomes_a_take_samba_and_other_tools_read(
    c3d_dir: Path, cmu_store: Path, tmp_path: Path, capsys
) -> None:
    out = tmp_path / "85_02.mcap"
    code, printed, err = run(
        capsys, "reconstruct", str(c3d_dir / "85_02.c3d"), "--db", str(cmu_store), "-o", str(out)
    )
    assert code == 0, err
    assert "85_02: 203 frames at 30 fps" in printed and "skin offsets from 60" in printed
    take = read_take(out)
    assert len(take) == 203 and take.fps == 30.0
    offsets = SkinOffsets.from_dict(json.loads(take.meta["skin_offsets"]))
    assert offsets.frames == 60
    knees = offsets.offsets[4:6, 0]  # lateral knee markers sit outside the knee
    assert knees[0] > 0.0 > knees[1]
    poses = take.poses
    feet = poses[:, 11:13, 1].min(axis=1)
    assert abs(np.percentile(feet, 10)) < 0.03  # feet on the floor (ankles at y = 0)
    head_above_hips = poses[:, 0, 1] > poses[:, 7:9, 1].mean(axis=1)
    assert head_above_hips.mean() > 0.8  # upright, but for the take's flips
    assert np.median(poses[:, 0, 1]) > 1.2  # a standing adult's head joint
    recorded = read_recorded_markers(out)  # the markers recorded beside the poses
    c3d = read_c3d(c3d_dir / "85_02.c3d").resampled(30.0)
    assert np.allclose(recorded.markers[..., [0, 2]], c3d.markers[..., [0, 2]], atol=1e-4)
    again = tmp_path / "again.bvh"  # a recorded take's markers reconstruct as well
    code, printed, err = run(
        capsys, "reconstruct", str(out), "--db", str(cmu_store), "-o", str(again)
    )
    assert code == 0, err
    assert read_bvh(again).n_frames >= 203 and "203 frames at 30 fps" in printed


@pytest.mark.parametrize("suffix", [".bvh", ".glb", ".usda"])
def test_a_c3d_take_exports_through_the_writers(
    suffix: str, c3d_dir: Path, cmu_store: Path, tmp_path: Path, capsys
) -> None:
    out = tmp_path / f"85_02{suffix}"
    argv = ["reconstruct", str(c3d_dir / "85_02.c3d"), "--db", str(cmu_store), "-o", str(out)]
    code, printed, err = run(capsys, *argv, "--method", "samba")
    assert code == 0, err
    assert out.stat().st_size > 1000 and f"wrote {out}" in printed
    if suffix == ".bvh":
        bvh = read_bvh(out)
        assert bvh.n_frames >= 203 and bvh.fps == 30.0


def test_a_take_with_a_fifth_of_its_markers_gone_in_runs_still_has_every_frame(
    c3d_dir: Path, cmu_store: Path
) -> None:
    whole = read_c3d(c3d_dir / "85_12.c3d").resampled(30.0)
    truth = reference_joints(whole)[:600]
    take = replace(whole, markers=whole.markers[:600].copy())
    rng = np.random.default_rng(7)
    gone = np.zeros(take.markers.shape[:2], dtype=bool)
    while gone.mean() < 0.2:  # runs of 1-30 frames of one marker
        marker, start, length = rng.integers(8), rng.integers(600), rng.integers(1, 31)
        gone[start : start + length, marker] = True
    gone[300:360] = True  # and two seconds of nothing at all
    take.markers[gone] = np.nan
    chosen = method("best")
    reconstructor = chosen.build(SessionIndexes().index(cmu_store, chosen.mirrored_database))
    result = reconstruct_marker_take(take, reconstructor, progress=False)
    assert result.poses.shape == (600, 13, 3) and np.isfinite(result.poses).all()
    assert result.filled.sum() > 0.5 * (gone.sum() - gone[300:360].sum())  # most gaps ...
    assert not result.filled[300:360].any()
    assert result.predicted[300:360].all() and not result.confident[result.predicted].any()
    assert result.predicted.sum() < 70  # ... were filled, so only those frames are predicted
    full = reconstruct_marker_take(replace(take, markers=whole.markers[:600]), reconstructor)
    error = np.linalg.norm(result.poses + result.floor * UP - truth, axis=-1).mean(axis=1)
    error_full = np.linalg.norm(full.poses + full.floor * UP - truth, axis=-1).mean(axis=1)
    outside = np.r_[0:300, 360:600]  # where markers were seen, gaps cost a few centimetres
    assert error[outside].mean() < error_full[outside].mean() + 0.04


def test_bad_input_gets_one_line_and_writes_nothing(
    c3d_dir: Path, cmu_store: Path, tmp_path: Path, capsys
) -> None:
    broken = tmp_path / "broken.c3d"
    broken.write_bytes((c3d_dir / "85_02.c3d").read_bytes()[:3000])
    out = tmp_path / "out.mcap"
    code, _, err = run(capsys, "reconstruct", str(broken), "--db", str(cmu_store), "-o", str(out))
    assert code == 1 and err.count("\n") == 1 and str(broken) in err
    assert not out.exists()
    text = tmp_path / "take.txt"
    text.write_text("not markers")
    code, _, err = run(capsys, "reconstruct", str(text), "--db", str(cmu_store), "-o", str(out))
    assert code == 1 and ".c3d" in err and not out.exists()
    fake = tmp_path / "fake.mcap"
    fake.write_bytes(b"\x89MCAP0\r\n" + bytes(100))
    code, _, err = run(capsys, "reconstruct", str(fake), "--db", str(cmu_store), "-o", str(out))
    assert code == 1 and err.count("\n") == 1 and str(fake) in err and not out.exists()
    existing = tmp_path / "kept.bvh"
    existing.write_text("keep me")
    code, _, err = run(
        capsys,
        "reconstruct",
        str(c3d_dir / "85_02.c3d"),
        "--db",
        str(cmu_store),
        "-o",
        str(existing),
    )
    assert code == 1 and "already exists" in err and existing.read_text() == "keep me"
    code, _, err = run(
        capsys,
        "reconstruct",
        str(c3d_dir / "85_02.c3d"),
        "--db",
        str(cmu_store),
        "-o",
        str(out),
        "--calibration",
        "60:62",
    )
    assert code == 1 and "calibration stretch 60-62 s starts after" in err and not out.exists()
