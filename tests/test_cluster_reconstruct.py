"""`samba reconstruct TAKE... --out-dir DIR --workers N` (Dask distributed): one task per
marker take on a `LocalCluster(n_workers=2, processes=True)`, the store read by path on
each worker; the takes written are those of the in-process run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from samba.cli import main
from samba.ingest import read_take

TAKES = ("85_02.c3d", "85_12.c3d")
"""The two real C3D marker takes of the shared data."""


@pytest.mark.slow
def test_takes_reconstructed_on_workers_are_those_reconstructed_here(
    c3d_dir: Path, cmu_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    takes = [str(c3d_dir / name) for name in TAKES]
    here, there = tmp_path / "here", tmp_path / "there"
    common = ["reconstruct", *takes, "--db", str(cmu_store), "--method", "samba"]
    assert main([*common, "--out-dir", str(here)]) == 0
    assert main([*common, "--out-dir", str(there), "--workers", "2"]) == 0
    out = capsys.readouterr().out
    assert out.count("wrote ") == 2 * len(TAKES)
    for name in TAKES:
        mine, theirs = (
            read_take(there / f"{Path(name).stem}.mcap"),
            read_take(here / f"{Path(name).stem}.mcap"),
        )
        assert len(mine) > 100
        assert np.array_equal(mine.poses, theirs.poses)


def test_several_takes_to_one_file_is_one_line(
    c3d_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    takes = [str(c3d_dir / name) for name in TAKES]
    out = tmp_path / "one.mcap"
    code = main(["reconstruct", *takes, "--db", str(tmp_path), "-o", str(out), "--workers", "2"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.strip().splitlines() == [
        "samba: error: --output: 2 takes cannot go to one file; give --out-dir DIR"
    ]
    assert not out.exists()
