"""Real marker takes from C3D (`samba.ingest.read_c3d`): the shared CMU takes, units,
up axis, missing markers, subject prefixes, marker sets, and bad files that name
themselves; a fuzz test in which only our error type escapes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from c3d_fixtures import LABELS, WRIST_HALF_WIDTH, c3d_bytes, walk_points
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from samba.base.errors import SambaError
from samba.body.skeleton import MARKER_NAMES, markers_of
from samba.ingest.c3d_take import read_c3d
from samba.ingest.errors import C3dError
from samba.ingest.marker_sets import MarkerSet
from samba.synthetic.motions import generate


@pytest.mark.parametrize(("name", "frames"), [("85_02", 810), ("85_12", 4499)])
def test_the_shared_cmu_takes_read_as_eight_markers_upright_in_meters(
    c3d_dir: Path, name: str, frames: int
) -> None:
    take = read_c3d(c3d_dir / f"{name}.c3d")
    assert len(take) == frames and take.fps == 120.0 and len(take.labels) == 41
    assert "LSHO" in take.labels and "Male:LSHO" not in take.labels  # subject prefix gone
    assert take.markers.shape == (frames, 8, 3) and np.isfinite(take.markers).all()
    shoulders, feet = take.markers[:, :2, 1].mean(), take.markers[:, 6:, 1].mean()
    assert 0.6 < shoulders - feet < 1.6  # meters, +Y up: acromion above ankle (85_12 dances low)
    width = np.linalg.norm(take.markers[:, 0] - take.markers[:, 1], axis=-1)
    assert 0.25 < np.median(width) < 0.5  # shoulder markers a shoulder width apart
    wrist = (take.point("LWRA") + take.point("LWRB")) / 2
    np.testing.assert_allclose(take.markers[:, 2], wrist)  # wrist = midpoint of its two


def test_a_written_take_comes_back_in_meters_y_up_with_missing_markers_nan(
    tmp_path: Path,
) -> None:
    points = walk_points()
    for units in ("mm", "cm", "m"):
        path = tmp_path / f"walk_{units}.c3d"
        path.write_bytes(c3d_bytes(points, units=units, missing=((3, 0), (5, 2))))
        take = read_c3d(path)
        assert take.meta["units"] == units
        assert np.isnan(take.points[3, 0]).all() and np.isnan(take.markers[3, 0]).all()
        np.testing.assert_allclose(take.markers[5, 2], points[5, 3], atol=1e-5)  # LWRB alone
        keep = ~np.isnan(take.points[..., 0])
        np.testing.assert_allclose(take.points[keep], points[keep], atol=1e-5)
    poses = generate("walk", seconds=1.0, seed=4).poses[:30]
    expected = markers_of(poses).astype(np.float64)  # the wrist pair's midpoint is the joint
    expected[3, 0] = np.nan
    expected[5, 2, 0] -= WRIST_HALF_WIDTH  # frame 5: LWRA missing, LWRB alone
    got = read_c3d(tmp_path / "walk_m.c3d").markers
    known = ~np.isnan(expected)
    np.testing.assert_allclose(got[known], expected[known], atol=1e-5)


def test_a_marker_set_file_maps_other_labels(tmp_path: Path) -> None:
    labels = tuple(label.replace("SHO", "_Shoulder") for label in LABELS)
    path = tmp_path / "lab.c3d"
    path.write_bytes(c3d_bytes(walk_points(), labels=labels))
    with pytest.raises(C3dError) as err:
        read_c3d(path)
    assert str(err.value).startswith(f"{path}: marker set 'plug-in-gait' finds no label for ")
    assert "l_shoulder (LSHO); r_shoulder (RSHO)" in err.value.problem
    assert "write a marker-set TOML file" in err.value.problem
    mapping = tmp_path / "lab.toml"
    mapping.write_text(
        'name = "lab"\n[markers]\nl_shoulder = "L_Shoulder"\nr_shoulder = "R_Shoulder"\n'
        'l_wrist = ["LWRA", "LWRB"]\nr_wrist = ["RWRA", "RWRB"]\nl_knee = "LKNE"\n'
        'r_knee = "RKNE"\nl_foot = "LANK"\nr_foot = "RANK"\n'
    )
    take = read_c3d(path, MarkerSet.from_toml(mapping))
    assert take.marker_set == "lab" and np.isfinite(take.markers).all()


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("[markers\n", "not valid TOML"),
        ("name = 'x'\n", "needs a [markers] table"),
        ("[markers]\nl_shoulder = 'A'\n", "[markers] does not map r_shoulder, l_wrist"),
        ("[markers]\nl_hand = 'A'\n", "unknown markers ['l_hand']"),
        (
            "[markers]\n" + "".join(f"{m} = 3\n" for m in MARKER_NAMES),
            "marker l_shoulder must map to a label or a list of labels",
        ),
    ],
)
def test_bad_marker_set_files_are_named(tmp_path: Path, text: str, problem: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(C3dError) as err:
        MarkerSet.from_toml(path)
    assert str(err.value).startswith(f"{path}: ") and problem in err.value.problem


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (b"", "not a readable C3D file"),
        (b"HIERARCHY\nROOT Hips\n", "not a readable C3D file"),
        ("truncated", "not a readable C3D file"),
        ("inches", "POINT:UNITS is 'in'"),
    ],
)
def test_bad_files_name_the_file_and_the_problem(
    tmp_path: Path, content: bytes | str, problem: str
) -> None:
    path = tmp_path / "bad.c3d"
    if content == "truncated":
        content = c3d_bytes(walk_points())[:700]
    elif content == "inches":
        content = c3d_bytes(walk_points(), units="in")
    path.write_bytes(content)
    with pytest.raises(C3dError) as err:
        read_c3d(path)
    assert str(err.value).startswith(f"{path}: ") and problem in err.value.problem
    with pytest.raises(C3dError, match="cannot read file"):
        read_c3d(tmp_path / "missing.c3d")


BASE = c3d_bytes(walk_points(8))


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    cut=st.integers(min_value=0, max_value=len(BASE)),
    flips=st.lists(st.tuples(st.integers(0, len(BASE) - 1), st.integers(0, 255)), max_size=12),
)
def test_mangled_files_import_or_raise_our_error(tmp_path: Path, cut: int, flips: list) -> None:
    """Cut anywhere, bytes overwritten anywhere: a take or a `SambaError` naming the file."""
    data = bytearray(BASE[:cut] if cut < len(BASE) else BASE)
    for where, value in flips:
        if where < len(data):
            data[where] = value
    path = tmp_path / "fuzz.c3d"
    path.write_bytes(bytes(data))
    try:
        take = read_c3d(path)
    except SambaError as exc:
        assert str(exc).startswith(f"{path}: ")
        return
    assert take.markers.shape[1:] == (8, 3)
