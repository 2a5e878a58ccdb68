"""The `samba` command line: what a user types and sees."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from samba.cli import main
from samba.db.store import PoseStore
from samba.export.gltf_reader import read_glb_joint_positions
from samba.export.gltf_writer import write_glb
from samba.export.humanoid import BONE_INDEX, HumanoidRig
from samba.export.motion import HumanoidMotion
from samba.export.usd_reader import read_usd_joint_positions
from samba.ingest.mcap_take import read_take


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """Run `samba argv...` in-process; returns (exit status, stdout, stderr)."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def store_with_cmu(tmp_path: Path, cmu_files: list[Path], capsys) -> Path:
    store = tmp_path / "store"
    assert run(capsys, "db", "init", str(store))[0] == 0
    picked = [
        str(f)
        for f in cmu_files
        if f.name in ("cgspeed_131_01.bvh", "iclone_002_01.bvh", "daz_salsa_10.bvh")
    ]
    code, out, _ = run(capsys, "db", "import", str(store), *picked, "--mirror", "--no-progress")
    assert code == 0, out
    return store


def test_import_prints_a_per_file_summary(store_with_cmu: Path, capsys) -> None:
    code, out, _ = run(capsys, "db", "ls", str(store_with_cmu))
    assert code == 0
    assert "cgspeed_131_01" in out and "iclone_002_01 (mirrored)" in out
    assert "6 takes" in out
    code, out, _ = run(capsys, "db", "stats", str(store_with_cmu), "--json")
    stats = json.loads(out)
    assert stats["takes"] == 6 and stats["mirrored_takes"] == 3 and stats["index_fresh"]


def test_reimport_is_a_no_op_and_bad_files_fail_alone(
    store_with_cmu: Path, cmu_dir: Path, tmp_path: Path, capsys
) -> None:
    broken = tmp_path / "broken.bvh"
    broken.write_bytes((cmu_dir / "cgspeed_131_02.bvh").read_bytes()[:300_000])
    before = PoseStore.open(store_with_cmu)
    code, out, err = run(
        capsys,
        "db",
        "import",
        str(store_with_cmu),
        str(cmu_dir / "cgspeed_131_01.bvh"),
        str(broken),
        str(cmu_dir / "iclone_002_02.bvh"),
        "--no-progress",
    )
    assert code == 1  # one file failed
    (error,) = err.splitlines()  # on stderr too, for scripts that read only it
    assert error.startswith(f"samba: error: {broken}:") and "truncated" in error
    lines = out.splitlines()
    assert any("cgspeed_131_01" in ln and "duplicate" in ln for ln in lines)
    assert any("broken.bvh" in ln and "failed" in ln and "truncated" in ln for ln in lines)
    assert any("iclone_002_02" in ln and "added" in ln for ln in lines)
    after = PoseStore.open(store_with_cmu)
    assert len(after.takes) == len(before.takes) + 1
    assert after.verify().ok


def test_show_label_query_rm(store_with_cmu: Path, capsys) -> None:
    code, out, _ = run(capsys, "db", "show", str(store_with_cmu), "daz_salsa_10", "--json")
    info = json.loads(out)
    assert info["rig"] == "daz" and info["meta"]["units"] == "cm"
    code, out, _ = run(
        capsys,
        "db",
        "label",
        str(store_with_cmu),
        f"#{info['id']}",
        "--action",
        "salsa",
        "--tag",
        "dance",
        "--tag",
        "couple",
    )
    assert code == 0 and "salsa" in out
    assert PoseStore.open(store_with_cmu).take(info["id"]).tags == ("couple", "dance")

    code, out, _ = run(
        capsys,
        "db",
        "query",
        str(store_with_cmu),
        "--pose",
        f"#{info['id']}:40",
        "--drop",
        "l_wrist",
        "-k",
        "3",
        "--json",
    )
    hits = json.loads(out)
    assert code == 0 and len(hits) == 3
    assert hits[0]["take"] == "daz_salsa_10" and hits[0]["distance_m"] < 1e-4

    code, out, _ = run(capsys, "db", "rm", str(store_with_cmu), "daz_salsa_10")
    assert code == 0 and "removed takes" in out
    assert "daz_salsa_10" not in [t.name for t in PoseStore.open(store_with_cmu).takes]
    code, out, _ = run(capsys, "db", "verify", str(store_with_cmu))
    assert code == 0 and "ok" in out


def test_query_with_explicit_markers(store_with_cmu: Path, capsys) -> None:
    store = PoseStore.open(store_with_cmu)
    pose = store.poses[100]
    text = ";".join(",".join(f"{v:.5f}" for v in pose[j]) for j in (1, 2, 5, 6, 9, 10, 11, 12))
    code, out, _ = run(capsys, "db", "query", str(store_with_cmu), "--markers", text, "-k", "2")
    assert code == 0 and "8 of 8 markers present" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["db", "ls", "{tmp}/nothing"], "no pose store here"),
        (["db", "init", "{store}"], "already exists"),
        (["db", "query", "{store}", "--markers", "1,2,3"], "expected 8"),
        (["db", "query", "{store}", "--pose", "#1:99999"], "has no frame 99999"),
        (["db", "query", "{store}", "--pose", "#1:0", "--drop", "nose"], "unknown marker"),
        (["db", "query", "{store}", "--pose", "#1:0", "-k", "0"], "samba: error: -k: k must be"),
        (["db", "show", "{store}", "no-such-take"], "no take named 'no-such-take'"),
        (["db", "import", "{store}", "{tmp}/missing.bvh", "--no-progress"], None),
        (["db", "import", "{store}", "{tmp}", "--rig", "nonsense"], "unknown rig"),
        (
            ["db", "import", "{store}", "{tmp}", "--fps", "-3"],
            "--fps: frame rate -3 fps is outside",
        ),
    ],
)
def test_bad_input_gives_one_clear_line(
    store_with_cmu: Path, tmp_path: Path, capsys, argv: list[str], message: str | None
) -> None:
    argv = [a.format(tmp=tmp_path, store=store_with_cmu) for a in argv]
    before = [t.to_dict() for t in PoseStore.open(store_with_cmu).takes]
    code, out, err = run(capsys, *argv)
    assert code == 1
    if message:
        assert message in err and err.startswith("samba: error:")
        assert "Traceback" not in err
    else:
        assert "failed" in out
    assert [t.to_dict() for t in PoseStore.open(store_with_cmu).takes] == before


def test_wrong_flag_exits_2_without_traceback(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "samba.cli", "db", "ls", str(tmp_path), "--bogus"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2
    assert "samba db ls: error: unrecognized arguments: --bogus" in result.stderr
    assert result.stderr.startswith("usage: samba db ls ")  # the subcommand's usage
    assert "Traceback" not in result.stderr


def test_output_into_a_reader_that_left_ends_quietly(store_with_cmu: Path) -> None:
    # `samba db ls STORE | head -1`: head exits after one line; samba must not print
    # "Broken pipe" or a traceback, and exits 0. Here the reader is gone before the start.
    read, write = os.pipe()
    os.close(read)
    try:
        result = subprocess.run(
            [sys.executable, "-m", "samba.cli", "db", "ls", str(store_with_cmu)],
            stdout=write,
            stderr=subprocess.PIPE,
            text=True,
            timeout=120,
        )
    finally:
        os.close(write)
    assert result.returncode == 0
    assert result.stderr == ""


def test_an_unknown_demo_motion_is_refused_before_anything_is_built(tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["demo", "--motion", "dance", "--out-dir", str(tmp_path / "demo")])
    assert exit_.value.code == 2
    assert "'dance' is neither a built-in motion" in capsys.readouterr().err
    assert not (tmp_path / "demo").exists()


@pytest.mark.slow
def test_demo_captures_live_and_writes_the_take_and_exports(tmp_path: Path, capsys) -> None:
    earlier = tmp_path / "cameras.toml"
    earlier.write_text("an earlier demo's")
    argv = ("demo", "--out-dir", str(tmp_path), "--seconds", "1.5", "--vmc", "127.0.0.1:9")
    code, out, err = run(capsys, *argv)
    assert code == 1 and out == ""
    assert err == (
        f"samba: error: {earlier}: already exists (an earlier demo); --force overwrites the "
        "demo's files, or give --out-dir another folder\n"
    )
    assert list(tmp_path.iterdir()) == [earlier]
    code, out, _ = run(capsys, *argv, "--force")
    assert code == 0
    assert f"all kept in {tmp_path}/" in out
    assert "frames out: 90 of 90" in out and "VMC frames received: 90" in out
    assert (tmp_path / "takes" / "demo" / "demo_walk.mcap").is_file()
    assert read_take(tmp_path / "takes" / "demo" / "demo_walk.mcap").poses.shape == (90, 13, 3)
    assert read_usd_joint_positions(tmp_path / "exports" / "demo_walk.usda")[1].shape[0] == 90
    assert read_glb_joint_positions(tmp_path / "exports" / "demo_walk.glb")[1].shape[0] == 90
    error = re.search(r"joint error against the truth: mean ([0-9.]+) cm", out)
    assert error and float(error.group(1)) < 5.0


def test_an_unwritable_place_gives_one_clear_line(tmp_path: Path, capsys) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    (locked / "file").write_text("x")
    code, _, err = run(capsys, "db", "init", str(locked / "file" / "store"))
    assert code == 1
    assert err.startswith("samba: error:") and "Traceback" not in err


@pytest.mark.slow
def test_demo_with_an_avatar_streams_and_exports_onto_it(
    tmp_path: Path, capsys, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`samba demo --avatar FILE`: the exports carry the avatar's skeleton (here one whose
    Hips joint sits 12 cm above its legs), with its feet on the floor."""
    mannequin = HumanoidRig.from_body()
    rest = mannequin.rest.copy()
    rest[BONE_INDEX["Hips"], 1] += 0.12
    rig = HumanoidRig(rest=rest, tips=mannequin.tips)
    avatar = tmp_path / "tall-hips.glb"
    write_glb(
        avatar, HumanoidMotion(rig, np.tile([0.0, 0.0, 0.0, 1.0], (1, 17, 1)), rest[:1], 30.0)
    )
    monkeypatch.chdir(tmp_path)  # the demo's files go to ./samba-demo by default
    code, out, _ = run(
        capsys,
        "demo",
        "--seconds",
        "1.5",
        "--vmc",
        "127.0.0.1:9",
        "--avatar",
        str(avatar),
    )
    assert code == 0 and "frames out: 90 of 90" in out
    names, joints = read_glb_joint_positions(tmp_path / "samba-demo/exports/demo_walk.glb")
    hips, feet = names.index("Hips"), [names.index("LeftFoot"), names.index("RightFoot")]
    leg = names.index("LeftUpperLeg")
    offset = np.linalg.norm(joints[:, hips] - joints[:, leg], axis=-1)
    np.testing.assert_allclose(offset, np.linalg.norm(rest[hips] - rest[leg]), atol=1e-4)
    assert abs(np.median(joints[:, feet, 1].min(axis=1)) - rig.ankle_height) < 0.01
