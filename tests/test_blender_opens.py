"""A real marker take reconstructed by `samba reconstruct` opens in Blender (its own BVH
and glTF importers, `bpy` in a venv of its own: it needs numpy < 2) with the feet on the
floor and the subject upright."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from samba.cli import main

pytestmark = pytest.mark.slow  # benchmark-like or end to end: CI runs it

BPY = "bpy==5.0.1"
MEASURE = Path(__file__).with_name("blender_measure.py")


@pytest.fixture(scope="session")
def blender() -> Path:
    """The Python of a venv holding Blender as a module (`bpy`), made once in a cache
    folder under the system temp dir; fails with pip's output when it cannot be made."""
    if sys.version_info[:2] != (3, 11):
        pytest.skip(f"{BPY} is built for Python 3.11 only")
    home = Path(tempfile.gettempdir()) / "samba-test-tools" / BPY.replace("==", "-")
    python = home / "bin" / "python"
    if not (home / "ready").is_file():
        steps = [[sys.executable, "-m", "venv", "--clear", str(home)]]
        steps.append([str(python), "-m", "pip", "install", "-q", BPY])
        for step in steps:
            done = subprocess.run(step, capture_output=True, text=True)
            if done.returncode != 0:
                pytest.fail(f"{' '.join(step)} failed:\n{done.stdout}\n{done.stderr}")
        (home / "ready").write_text(BPY)
    return python


def test_a_reconstructed_c3d_take_opens_in_blender_feet_down_head_up(
    blender: Path, c3d_dir: Path, cmu_store: Path, tmp_path: Path, capsys
) -> None:
    outputs = [tmp_path / "85_02.bvh", tmp_path / "85_02.glb"]
    for out in outputs:
        argv = ["reconstruct", str(c3d_dir / "85_02.c3d"), "--db", str(cmu_store), "-o", str(out)]
        assert main(argv) == 0, capsys.readouterr().err
    done = subprocess.run(
        [str(blender), str(MEASURE), *map(str, outputs)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr[-2000:]
    found = [json.loads(line[6:]) for line in done.stdout.splitlines() if line.startswith("SAMBA ")]
    assert [Path(f["path"]).suffix for f in found] == [".bvh", ".glb"]
    assert found[0]["frames"] == 203  # 6.8 s at 30 fps (the glTF importer resamples to 24 fps)
    for seen in found:
        assert seen["bones"] >= 17
        assert -0.02 < seen["ankle_p10_m"] < 0.10  # the feet stand on the floor ...
        assert seen["ankle_median_m"] < 0.15  # ... and are not floating
        assert seen["head_above_hips"] > 0.85  # upright but for the take's flips
        assert 1.3 < seen["head_median_m"] < 1.8
