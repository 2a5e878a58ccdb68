"""`samba eval`: the evaluation protocol on real BVH files and on in-memory takes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from samba.base.errors import InputError
from samba.cli import main
from samba.db.index import PoseIndex
from samba.evaluation.experiment import evaluate, sweep_points
from samba.reconstruct.methods import METHODS, method
from samba.synthetic.motions import generate

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PICKED = ("cgspeed_131_01.bvh", "iclone_002_01.bvh", "daz_salsa_10.bvh")


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """Run `samba argv...` in-process; returns (exit status, stdout, stderr)."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def picked(cmu_files: list[Path]) -> list[str]:
    """Three real CMU files of three rigs."""
    return [str(f) for f in cmu_files if f.name in PICKED]


def test_eval_prints_tables_writes_json_and_plots(picked, tmp_path: Path, capsys) -> None:
    out_json, plots = tmp_path / "out.json", tmp_path / "plots"
    code, out, err = run(
        capsys,
        "eval",
        "--train",
        *picked,
        "--test",
        picked[0],
        "--methods",
        ",".join(METHODS),
        "--max-frames",
        "60",
        "--json",
        str(out_json),
        "--plots",
        str(plots),
    )
    assert code == 0, err
    assert "leave-one-take-out" in out
    for heading in ("MPJPE cm", "per take", "per joint", "l_elbow", "cgspeed_131_01"):
        assert heading in out
    overall = out.split("\n\n")[1]
    for name in METHODS:
        assert any(line.startswith(f"{name} ") for line in overall.splitlines()), name
    assert "pseudo-poses (samba vs chai)" in out and "best vs samba" in out

    document = json.loads(out_json.read_text())
    assert set(document["methods"]) == set(METHODS)
    for summary in document["methods"].values():
        assert math.isfinite(summary["mpjpe_cm"]) and summary["frames"] == 60
    assert document["settings"]["left_out"] == ["cgspeed_131_01"]
    assert document["settings"]["methods"]["best"]["k"] == 30
    assert document["sweeps"] == {}
    pngs = sorted(p.name for p in plots.glob("*.png"))
    assert pngs == ["error_per_joint.png", "error_time_cgspeed_131_01.png"]
    for png in plots.glob("*.png"):
        assert png.read_bytes().startswith(PNG_SIGNATURE)
    assert not list(tmp_path.glob(".*tmp"))


def test_eval_sweeps_draw_the_papers_figures(picked, tmp_path: Path, capsys) -> None:
    out_json, plots = tmp_path / "sweep.json", tmp_path / "plots"
    code, out, err = run(
        capsys,
        "eval",
        "--train",
        *picked[1:],
        "--test",
        picked[0],
        "--methods",
        "samba",
        "--sweep-k",
        "1,10",
        "--sweep-n",
        "1,5",
        "--max-frames",
        "30",
        "--json",
        str(out_json),
        "--plots",
        str(plots),
    )
    assert code == 0, err
    assert "held-out test set" in out
    assert "K sweep" in out and "N sweep" in out and "K=30 cm" in out
    sweeps = json.loads(out_json.read_text())["sweeps"]
    assert [(p["k"], p["n"]) for p in sweeps["k"]] == [(1, 10), (10, 10)]
    assert [(p["k"], p["n"]) for p in sweeps["n"]] == [(k, n) for k in (10, 20, 30) for n in (1, 5)]
    for name in ("fig8_k_sweep.png", "fig9_n_sweep.png"):
        assert (plots / name).read_bytes().startswith(PNG_SIGNATURE)


def test_eval_input_errors_name_the_input(picked, tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["eval", "--train", *picked, "--test", picked[0], "--methods", "nn,magic"])
    assert exc.value.code == 2
    assert "magic" in capsys.readouterr().err

    for flag, value in (("--dropout", "1.0"), ("--K", "0"), ("--sweep-n", "1,-2")):
        with pytest.raises(SystemExit) as exc:
            main(["eval", "--train", *picked, "--test", picked[0], flag, value])
        assert exc.value.code == 2
        assert flag in capsys.readouterr().err

    missing = tmp_path / "nowhere.bvh"
    code, _, err = run(capsys, "eval", "--train", *picked, "--test", str(missing))
    assert code == 1 and "nowhere.bvh" in err and len(err.strip().splitlines()) == 1

    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = run(capsys, "eval", "--train", *picked, "--test", str(empty))
    assert code == 1 and "--test" in err and "no .bvh or .c3d files" in err

    a_file = tmp_path / "plots.txt"
    a_file.write_text("not a folder")
    code, _, err = run(
        capsys, "eval", "--train", *picked, "--test", picked[0], "--plots", str(a_file)
    )
    assert (
        code == 1 and f"--plots: {a_file} is a file" in err and len(err.strip().splitlines()) == 1
    )


def synthetic(seed: int) -> tuple[str, np.ndarray]:
    """A 3 s synthetic walk at 30 fps, named after its seed."""
    return f"walk{seed}", generate("walk", 3, 30, seed=seed).poses


def test_evaluate_in_memory_leaves_each_test_take_out() -> None:
    takes = [synthetic(1), synthetic(2)]
    runs = {name: method(name) for name in METHODS}
    loto = evaluate(takes, takes, runs, PoseIndex.build, seed=3)
    assert loto.left_out == ("walk1", "walk2")
    assert loto.mode.startswith("leave-one-take-out")
    summaries = loto.summaries
    assert set(summaries) == set(METHODS)
    for label, summary in summaries.items():
        assert summary["frames"] == 180, label
        assert 0 < summary["mpjpe_cm"] < 30, label
        assert set(summary["per_take_cm"]) == {"walk1", "walk2"}
    # with the test take itself in the database (under another name) nn finds its poses
    seen = evaluate(
        [takes[1], ("copy", takes[0][1])], takes, {"nn": method("nn")}, PoseIndex.build, seed=3
    )
    assert seen.left_out == ("walk2",) and seen.mode.startswith("mixed")
    assert (
        seen.summaries["nn"]["per_take_cm"]["walk1"] < 0.5 * summaries["nn"]["per_take_cm"]["walk1"]
    )
    # the capture depends only on the seed: the same run gives the same errors
    again = evaluate(takes, takes, {"chai": method("chai")}, PoseIndex.build, seed=3)
    np.testing.assert_array_equal(again.results["chai"][1].errors, loto.results["chai"][1].errors)


def test_evaluate_rejects_a_database_too_small() -> None:
    take = synthetic(1)
    with pytest.raises(InputError, match="no training take"):
        evaluate([take], [take], {"nn": method("nn")}, PoseIndex.build)
    with pytest.raises(InputError, match="K = 200"):
        evaluate(
            [synthetic(2)], [take], {"samba": method("samba").with_sizes(k=200)}, PoseIndex.build
        )


def test_sweep_points_reuse_equal_runs() -> None:
    runs = {"samba": method("samba"), "nn": method("nn")}
    sweeps = sweep_points(runs, [5, 10], [10], None)
    assert sweeps["k"] == [(5, 10, "samba K=5 N=10"), (10, 10, "samba")]
    assert sweeps["n"] == [
        (10, 10, "samba"),
        (20, 10, "samba K=20 N=10"),
        (30, 10, "samba K=30 N=10"),
    ]
    assert list(runs) == ["samba", "nn", "samba K=5 N=10", "samba K=20 N=10", "samba K=30 N=10"]
    assert runs["samba K=20 N=10"].config.k == 20


def test_an_error_names_the_file_as_typed_not_where_a_link_leads(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    real = tmp_path / "real"
    real.mkdir()
    (real / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    typed = tmp_path / "link" / "broken.bvh"
    (tmp_path / "link").symlink_to(real)
    code, _, err = run(capsys, "eval", "--train", str(typed), "--test", str(typed))
    assert code == 1 and err.startswith(f"samba: error: {typed}:"), err


def test_an_existing_json_is_not_overwritten_without_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    kept = tmp_path / "results.json"
    kept.write_text("earlier results")
    code, _, err = run(capsys, "eval", "--train", "x.bvh", "--test", "x.bvh", "--json", str(kept))
    assert code == 1 and err == f"samba: error: {kept}: already exists; --force overwrites\n"
    assert kept.read_text() == "earlier results"
