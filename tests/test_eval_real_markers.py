"""`samba eval` on real marker takes (C3D): raw, calibrated and synthetic-marker errors
against reference joint centres, with the offset-removed columns beside the raw ones."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from samba.base import InputError
from samba.body import joint_frames, markers_of
from samba.cli import main
from samba.db import PoseIndex
from samba.evaluation import MarkerTest, evaluate_markers, offset_removed_errors
from samba.reconstruct import method
from samba.synthetic.motions import generate

PICKED = ("cgspeed_131_01.bvh", "iclone_002_01.bvh", "daz_salsa_10.bvh")


def test_eval_scores_a_c3d_take_raw_calibrated_and_synthetic(
    cmu_files: list[Path], c3d_dir: Path, tmp_path: Path, capsys
) -> None:
    train = [str(f) for f in cmu_files if f.name in PICKED]
    out = tmp_path / "real.json"
    argv = ["eval", "--train", *train, "--test", str(c3d_dir / "85_02.c3d"), train[0]]
    code = main([*argv, "--methods", "nn,best", "--max-frames", "120", "--json", str(out)])
    printed = capsys.readouterr().out
    assert code == 0
    assert "real marker takes: 85_02 (120 frames)" in printed
    for words in ("real markers", "real, calibrated", "at reference centres", "offset removed"):
        assert words in printed
    assert "per take (MPJPE cm)" in printed  # the BVH test take got its own report
    doc = json.loads(out.read_text())
    real = doc["real_markers"]["methods"]["best"]
    assert doc["real_markers"]["calibration_frames"] == [0, 60]
    raw, calibrated, synthetic = (real[v] for v in ("raw", "calibrated", "synthetic"))
    assert synthetic["marker_cm"] < raw["marker_cm"]  # skin markers cost on their joints ...
    assert calibrated["marker_cm"] < raw["marker_cm"]  # ... which the calibration wins back
    for summary in (raw, calibrated, synthetic):
        assert summary["mpjpe_cm_removed"] <= summary["mpjpe_cm"] + 1e-9
        assert summary["frames"] == 120 and set(summary["per_joint_cm"]) >= {"head", "l_hip"}
    offsets = doc["real_markers"]["skin_offsets"]["best"]["85_02"]["offsets_m"]
    assert offsets["l_knee"][0] > 0.02 > -0.02 > offsets["r_knee"][0]  # lateral knee markers


def test_eval_with_3d_markers_and_a_bad_c3d(
    cmu_files: list[Path], c3d_dir: Path, tmp_path: Path, capsys
) -> None:
    train = [str(f) for f in cmu_files if f.name in PICKED]
    test = ["--test", str(c3d_dir / "85_02.c3d"), "--methods", "nn", "--max-frames", "90"]
    assert main(["eval", "--train", *train, *test, "--markers-3d"]) == 0
    assert "markers as recorded (3D)" in capsys.readouterr().out
    broken = tmp_path / "broken.c3d"
    broken.write_bytes(b"\x02\x50" + bytes(600))
    assert main(["eval", "--train", *train, "--test", str(broken)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(broken) in err
    code = main(["eval", "--train", *train, *test, "--calibration", "5:9"])
    assert code == 1 and "--calibration" in capsys.readouterr().err


def test_a_constant_offset_in_the_segment_frame_is_removed_and_nothing_else() -> None:
    truth = generate("walk", 3.0, 30.0, seed=2).poses.astype(np.float64)
    frames = joint_frames(truth)
    constant = np.array([0.0, 0.05, 0.02])
    moved = truth + np.einsum("fkij,j->fki", frames, constant)
    assert np.allclose(offset_removed_errors(moved, truth), 0.0, atol=1e-9)
    rng = np.random.default_rng(0)
    noisy = truth + rng.normal(scale=0.02, size=truth.shape)
    assert offset_removed_errors(noisy, truth).mean() > 0.02


def test_in_memory_real_takes_score_each_variant() -> None:
    database = generate("walk", 6.0, 30.0, seed=1).poses
    truth = generate("walk", 3.0, 30.0, seed=4).poses.astype(np.float64)
    skin = markers_of(truth) + np.array([0.0, 0.03, 0.0])
    test = MarkerTest("walk", truth, skin)
    runs = {"nn": method("nn")}
    result = evaluate_markers([("db", database)], [test], runs, PoseIndex.build, markers_3d=True)
    summaries = result.summaries()["nn"]
    assert set(summaries) == {"raw", "calibrated", "synthetic"}
    assert summaries["synthetic"]["marker_cm"] < summaries["raw"]["marker_cm"]
    with pytest.raises(InputError, match="outside"):
        evaluate_markers([("db", database)], [test], runs, PoseIndex.build, calibration=(80, 200))
