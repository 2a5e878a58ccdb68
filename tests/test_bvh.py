"""The BVH reader (`samba.ingest.bvh`): grammar, kinematics, and errors that name file and line."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from bvh_fixtures import HumanoidFixture, make_humanoid

from samba.base.errors import InputError, SambaError
from samba.ingest.bvh import BvhFile, parse_bvh, read_bvh
from samba.ingest.bvh_take import load_bvh_take
from samba.ingest.errors import BvhError

SOURCE = "walk.bvh"

TWO_JOINTS = """HIERARCHY
ROOT root
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT child
  {
    OFFSET 1 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 2 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.5
0 0 0 0 0 0 0 0 0
10 20 30 90 0 0 0 0 0
0 0 0 0 0 0 0 90 0
"""
"""Root at the origin; the child 1 along X; its End Site 2 along the child's Y."""


def _all(bvh: BvhFile) -> np.ndarray:
    """World positions (n, J, 3) of every joint, End Sites included."""
    return bvh.positions(list(range(len(bvh.joints))))


def _error(data: str | bytes, source: str = SOURCE) -> BvhError:
    """The `BvhError` that parsing `data` raises, checked to start with 'source:line:'."""
    with pytest.raises(BvhError) as info:
        parse_bvh(data, source=source)
    err = info.value
    assert isinstance(err, InputError) and isinstance(err, SambaError)
    assert err.source == source
    where = source if err.line is None else f"{source}:{err.line}"
    assert str(err).startswith(f"{where}: ")
    return err


def _line_of(text: str, needle: str, start: int = 1) -> int:
    """1-based number of the first line at or after `start` that contains `needle`."""
    lines = text.split("\n")
    return next(i + 1 for i in range(start - 1, len(lines)) if needle in lines[i])


@pytest.fixture(scope="module")
def walk() -> HumanoidFixture:
    """A 12-frame cmu-max humanoid in meters."""
    return make_humanoid("cmu-max", frames=12)


def _frame_line(text: str, frame: int) -> int:
    """1-based line number of motion frame `frame` in text without blank lines."""
    return _line_of(text, "Frame Time:") + 1 + frame


# --- grammar --------------------------------------------------------------------------------


def test_two_joint_example_matches_hand_computed_positions() -> None:
    bvh = parse_bvh(TWO_JOINTS, source=SOURCE)
    assert bvh.names == ("root", "child", "child_end")
    assert [j.parent for j in bvh.joints] == [-1, 0, 1]
    assert bvh.joints[2].end_site and bvh.joints[2].channels == ()
    assert bvh.n_frames == 3 and bvh.frame_time == 0.5 and bvh.fps == 2.0
    expected = [
        # rest: child 1 along X, End Site 2 above the child
        [[0, 0, 0], [1, 0, 0], [1, 2, 0]],
        # root moved to (10, 20, 30) and turned 90 degrees about Z: X -> Y, Y -> -X
        [[10, 20, 30], [10, 21, 30], [8, 21, 30]],
        # child turned 90 degrees about X: its Y -> Z, so the End Site moves to +Z
        [[0, 0, 0], [1, 0, 0], [1, 0, 2]],
    ]
    np.testing.assert_allclose(_all(bvh), expected, atol=1e-12)


@pytest.mark.parametrize(
    ("channels", "expected"),
    [
        # listed order composes intrinsically: Rz(90) @ Rx(90) takes Y to Z
        ("Zrotation Xrotation Yrotation", [0, 0, 1]),
        # the same two angles listed the other way round: Rx(90) @ Rz(90) takes Y to -X
        ("Xrotation Zrotation Yrotation", [-1, 0, 0]),
    ],
)
def test_rotation_channels_compose_in_listed_order(channels: str, expected: list[int]) -> None:
    text = (
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n"
        f"CHANNELS 3 {channels}\n"
        "JOINT b\n{\nOFFSET 0 1 0\nEnd Site\n{\nOFFSET 0 1 0\n}\n}\n}\n"
        "MOTION\nFrames: 1\nFrame Time: 0.1\n90 90 0\n"
    )
    np.testing.assert_allclose(_all(parse_bvh(text))[0, 1], expected, atol=1e-12)


def test_position_channels_on_a_non_root_joint_replace_its_offset_components() -> None:
    # The child's Yposition channel replaces the Y of its OFFSET (the MotionBuilder
    # convention); X and Z keep the OFFSET's values. Its Zrotation turns its End Site.
    text = """HIERARCHY
ROOT root
{
  OFFSET 0 0 0
  CHANNELS 3 Xposition Yposition Zposition
  JOINT child
  {
    OFFSET 1 7 2
    CHANNELS 2 Yposition Zrotation
    End Site
    {
      OFFSET 1 0 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.1
0 0 0 5 0
1 1 1 -3 90
"""
    positions = _all(parse_bvh(text))
    np.testing.assert_allclose(positions[0, 1], [1, 5, 2], atol=1e-12)
    np.testing.assert_allclose(positions[0, 2], [2, 5, 2], atol=1e-12)
    np.testing.assert_allclose(positions[1, 1], [2, -2, 3], atol=1e-12)
    np.testing.assert_allclose(positions[1, 2], [2, -1, 3], atol=1e-12)


def test_root_position_channels_replace_the_root_offset() -> None:
    text = TWO_JOINTS.replace("OFFSET 0 0 0", "OFFSET 100 100 100", 1)
    np.testing.assert_allclose(_all(parse_bvh(text)), _all(parse_bvh(TWO_JOINTS)), atol=1e-12)


def test_mixed_channel_orders_match_independent_kinematics() -> None:
    fixture = make_humanoid(channel_order=["XYZ", "ZXY", "YZX", "ZYX", "XZY", "YXZ"], frames=8)
    bvh = parse_bvh(fixture.text, source=SOURCE)
    orders = {"".join(c[0] for c in j.channels[-3:]) for j in bvh.joints if j.channels}
    assert orders == {"XYZ", "ZXY", "YZX", "ZYX", "XZY", "YXZ"}
    np.testing.assert_allclose(_all(bvh), fixture.file_positions, atol=1e-5)


@pytest.mark.parametrize("unit_scale", [1.0, 100.0])
def test_fixture_kinematics_match_for_every_joint(unit_scale: float) -> None:
    fixture = make_humanoid(frames=12, unit_scale=unit_scale, seed=3)
    bvh = parse_bvh(fixture.text, source=SOURCE)
    assert bvh.names == fixture.names
    np.testing.assert_allclose(_all(bvh), fixture.file_positions, atol=1e-5 * unit_scale)


def test_root_without_position_channels_stays_at_its_offset() -> None:
    fixture = make_humanoid(frames=6, root_position_channels=False)
    bvh = parse_bvh(fixture.text)
    assert bvh.joints[0].channels == ("Zrotation", "Xrotation", "Yrotation")
    positions = _all(bvh)
    np.testing.assert_allclose(positions, fixture.file_positions, atol=1e-5)
    np.testing.assert_allclose(positions[:, 0], np.broadcast_to(positions[0, 0], (6, 3)))


def test_end_sites_are_named_after_their_parent_and_carry_no_channels(walk) -> None:
    bvh = parse_bvh(walk.text)
    ends = [j for j in bvh.joints if j.end_site]
    assert [j.name for j in ends] == [
        "Head_end",
        "LeftWrist_end",
        "RightWrist_end",
        "LeftToe_end",
        "RightToe_end",
    ]
    assert all(j.channels == () and bvh.joints[j.parent].name + "_end" == j.name for j in ends)
    assert bvh.motion.shape == (12, 6 + 3 * 20)


def _blank_lines(text: str) -> str:
    """Blank lines (some with spaces) after every line of the hierarchy and every frame."""
    return text.replace("\n", "\n\n  \t\n")


def _keyword_case(text: str) -> str:
    """Keywords and channel names in other letter cases."""
    for old, new in [
        ("HIERARCHY", "hierarchy"),
        ("ROOT", "Root"),
        ("JOINT", "joint"),
        ("OFFSET", "Offset"),
        ("CHANNELS", "channels"),
        ("End Site", "END SITE"),
        ("Zrotation", "ZROTATION"),
        ("Xrotation", "xrotation"),
        ("Yposition", "YPosition"),
        ("MOTION", "motion"),
        ("Frames:", "FRAMES:"),
        ("Frame Time:", "frame time:"),
    ]:
        text = text.replace(old, new)
    return text


FORMATS: dict[str, Callable[[str], str]] = {
    "spaces": lambda t: t.replace("\t", "  "),
    "no indent": lambda t: "\n".join(ln.strip() for ln in t.split("\n")),
    "crlf": lambda t: t.replace("\n", "\r\n"),
    "bare cr": lambda t: t.replace("\n", "\r"),
    "blank lines": _blank_lines,
    "trailing spaces": lambda t: t.replace("\n", " \t \n"),
    "no final newline": lambda t: t.rstrip("\n"),
    "frames tab": lambda t: t.replace("Frames: ", "Frames:\t"),
    "frames no space": lambda t: t.replace("Frames: ", "Frames:"),
    "frame time tabs": lambda t: t.replace("Frame Time: ", "Frame\tTime:\t"),
    "keyword case": _keyword_case,
    "braces on joint lines": lambda t: t.replace("\n\t{", " {").replace("\n{", " {"),
}


@pytest.mark.parametrize("variant", list(FORMATS))
def test_formatting_variants_parse_to_the_same_file(walk, variant: str) -> None:
    text = FORMATS[variant](walk.text)
    assert text != walk.text
    bvh = parse_bvh(text, source=SOURCE)
    reference = parse_bvh(walk.text, source=SOURCE)
    assert bvh.names == reference.names
    assert bvh.frame_time == reference.frame_time
    np.testing.assert_array_equal(bvh.motion, reference.motion)
    for a, b in zip(bvh.joints, reference.joints, strict=True):
        np.testing.assert_array_equal(a.offset, b.offset)
        assert a.channels == b.channels


def test_scientific_notation_and_a_utf8_bom_are_read(walk) -> None:
    fixture = make_humanoid(frames=12, number_format=".6e")
    assert "e-01" in fixture.text
    bvh = parse_bvh(b"\xef\xbb\xbf" + fixture.text.encode(), source=SOURCE)
    np.testing.assert_allclose(_all(bvh), walk.file_positions, atol=1e-5)


def test_two_roots_are_read_as_two_trees(walk) -> None:
    prop = (
        "ROOT Prop\n{\n\tOFFSET 0 0 0\n\tCHANNELS 3 Xposition Yposition Zposition\n"
        "\tEnd Site\n\t{\n\t\tOFFSET 0 0.3 0\n\t}\n}\nMOTION"
    )
    head, tail = walk.text.split("MOTION")
    lines = tail.split("\n")
    frames = [f"{line} 1.0 {i}.5 -2.0" for i, line in enumerate(lines[3:-1])]
    text = head + prop + "\n".join(lines[:3] + frames) + "\n"
    bvh = parse_bvh(text, source=SOURCE)
    prop_index = bvh.names.index("Prop")
    assert bvh.joints[0].parent == -1 and bvh.joints[prop_index].parent == -1
    assert bvh.joints[prop_index].first_channel == bvh.motion.shape[1] - 3
    np.testing.assert_allclose(bvh.positions([prop_index])[:, 0, 1], np.arange(12) + 0.5)
    np.testing.assert_allclose(
        bvh.positions([prop_index + 1])[:, 0], np.array([[1.0, i + 0.8, -2.0] for i in range(12)])
    )
    np.testing.assert_allclose(_all(bvh)[:, :prop_index], walk.file_positions, atol=1e-5)


def test_two_root_file_imports_as_a_take(tmp_path: Path, walk) -> None:
    prop = "ROOT Prop\n{\nOFFSET 0 0 0\nCHANNELS 1 Yposition\n}\nMOTION"
    head, tail = walk.text.split("MOTION")
    lines = tail.split("\n")
    text = head + prop + "\n".join(lines[:3] + [ln + " 9" for ln in lines[3:-1]]) + "\n"
    path = tmp_path / "prop.bvh"
    path.write_text(text)
    take = load_bvh_take(path)
    np.testing.assert_allclose(take.poses, walk.positions, atol=1e-5)


def test_ancestry_lists_the_joints_and_their_ancestors_in_file_order(walk) -> None:
    bvh = parse_bvh(walk.text)
    index = {n: i for i, n in enumerate(bvh.names)}
    wrist, knee = index["LeftWrist"], index["RightKnee"]
    chain = ["Hips", "Spine", "Chest", "LeftCollar", "LeftShoulder", "LeftElbow", "LeftWrist"]
    assert bvh.ancestry([wrist]) == [index[n] for n in chain]
    assert bvh.ancestry([knee, wrist]) == sorted(
        [index[n] for n in chain] + [index["RightHip"], index["RightKnee"]]
    )
    assert bvh.ancestry([0]) == [0]


def test_positions_of_a_subset_keep_the_requested_order(walk) -> None:
    bvh = parse_bvh(walk.text)
    wanted = [bvh.names.index(n) for n in ("RightAnkle", "Head", "LeftWrist_end", "Hips")]
    positions = bvh.positions(wanted)
    assert positions.shape == (12, 4, 3)
    np.testing.assert_allclose(positions, walk.file_positions[:, wanted], atol=1e-5)


def test_read_bvh_reads_a_path(tmp_path: Path, walk) -> None:
    path = tmp_path / "walk.bvh"
    path.write_bytes(walk.text.replace("\n", "\r\n").encode())
    bvh = read_bvh(path)
    assert bvh.source == str(path)
    np.testing.assert_allclose(_all(bvh), walk.file_positions, atol=1e-5)


# --- errors: every one names the file and the line --------------------------------------------


def test_truncated_mid_frame_names_the_last_line(walk) -> None:
    cut = walk.text[: walk.text.rindex("\n", 0, -1) + 40]  # 40 characters into the last frame
    err = _error(cut)
    assert err.line == _frame_line(walk.text, 11)
    assert "truncated" in err.problem and "frame 11" in err.problem


def test_truncated_after_a_whole_frame_names_the_last_line(walk) -> None:
    lines = walk.text.split("\n")
    last = _frame_line(walk.text, 4)
    err = _error("\n".join(lines[:last]) + "\n")
    assert err.line == last
    assert "5 of the 12 frames" in err.problem


@pytest.mark.parametrize("cut_after", ["JOINT LeftKnee", "OFFSET 0.000000 -0.430000", "\t}"])
def test_truncated_inside_the_hierarchy_names_the_last_line(walk, cut_after: str) -> None:
    end = walk.text.index(cut_after) + len(cut_after)
    cut = walk.text[:end]
    err = _error(cut + "\n")
    assert err.line == cut.count("\n") + 1
    assert "hierarchy ends early" in err.problem


@pytest.mark.parametrize("ending", ["MOTION\n", "MOTION\nFrames: 12\n", "MOTION\nFrames: 12"])
def test_truncated_in_the_motion_header_names_the_last_line(walk, ending: str) -> None:
    cut = walk.text[: walk.text.index("MOTION")] + ending
    err = _error(cut + "\n\n")
    assert err.line == cut.rstrip().count("\n") + 1
    assert "file ends before" in err.problem


def test_header_without_any_frame_lines_names_the_frame_time_line(walk) -> None:
    cut = walk.text[: walk.text.index("Frame Time:")] + "Frame Time: 0.03333333\n"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing but the error reaches the user
        err = _error(cut)
    assert err.line == _line_of(walk.text, "Frame Time:")
    assert "file ends after 0 of the 12 frames" in err.problem


def test_channels_line_listing_too_few_names(walk) -> None:
    text = walk.text.replace(
        "CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 3 Zrotation Xrotation", 2
    )
    err = _error(text)
    assert err.line == _line_of(walk.text, "CHANNELS 3")
    assert "Spine declares 3 channels" in err.problem


def test_channels_line_listing_too_many_names(walk) -> None:
    text = walk.text.replace("CHANNELS 3 Zrotation", "CHANNELS 2 Zrotation", 1)
    err = _error(text)
    assert err.line == _line_of(walk.text, "CHANNELS 3")
    assert "'Yrotation'" in err.problem


@pytest.mark.parametrize(
    ("channels", "problem"),
    [
        ("CHANNELS three Zrotation Xrotation Yrotation", "not an integer"),
        ("CHANNELS 3 Zrotation Wrotation Yrotation", "'Wrotation' is not a channel name"),
        ("CHANNELS 3 Zrotation Xrotation Zrotation", "repeats a channel"),
    ],
)
def test_bad_channels_lines(walk, channels: str, problem: str) -> None:
    text = walk.text.replace("CHANNELS 3 Zrotation Xrotation Yrotation", channels, 1)
    err = _error(text)
    assert err.line == _line_of(walk.text, "CHANNELS 3")
    assert problem in err.problem


@pytest.mark.parametrize("change", [-1, 1])
def test_frame_with_too_few_or_too_many_values(walk, change: int) -> None:
    lines = walk.text.split("\n")
    bad = _frame_line(walk.text, 7)
    values = lines[bad - 1].split()
    lines[bad - 1] = " ".join(values[:-1] if change < 0 else [*values, "0.5"])
    err = _error("\n".join(lines))
    assert err.line == bad
    assert f"frame 7 has {len(values) + change} values" in err.problem
    assert f"declares {len(values)} channels" in err.problem


@pytest.mark.parametrize("token", ["abc", "1.2.3", "0x10", "1,5", "--1", "{"])
def test_non_numeric_value_in_a_frame(walk, token: str) -> None:
    lines = walk.text.split("\n")
    bad = _frame_line(walk.text, 3)
    values = lines[bad - 1].split()
    values[5] = token
    lines[bad - 1] = " ".join(values)
    err = _error("\n".join(lines))
    assert err.line == bad
    assert repr(token) in err.problem and "frame 3" in err.problem


@pytest.mark.parametrize("token", ["zero", "1e", "nan", "inf", "1e999"])
def test_bad_number_in_an_offset(walk, token: str) -> None:
    text = walk.text.replace("OFFSET 0.000000 0.220000", f"OFFSET {token} 0.220000", 1)
    err = _error(text)
    assert err.line == _line_of(walk.text, "OFFSET 0.000000 0.220000")
    assert "OFFSET of Chest" in err.problem and repr(token) in err.problem


@pytest.mark.parametrize("token", ["nan", "NaN", "inf", "-inf", "Infinity", "1e999"])
def test_nan_or_infinity_in_a_frame(walk, token: str) -> None:
    lines = walk.text.split("\n")
    bad = _frame_line(walk.text, 9)
    values = lines[bad - 1].split()
    values[10] = token
    lines[bad - 1] = " ".join(values)
    err = _error("\n".join(lines))
    assert err.line == bad
    assert "frame 9 holds NaN or infinity" in err.problem


def test_nan_line_is_right_with_blank_lines_between_frames(walk) -> None:
    text = walk.text.replace("\n", "\n\n")
    lines = text.split("\n")
    bad = _line_of(text, "Frame Time:") + 2 + 2 * 4  # frame 4 after blank lines
    values = lines[bad - 1].split()
    values[0] = "nan"
    lines[bad - 1] = " ".join(values)
    assert _error("\n".join(lines)).line == bad


def test_frames_says_more_than_present(walk) -> None:
    err = _error(walk.text.replace("Frames: 12", "Frames: 13"))
    assert err.line == _frame_line(walk.text, 11)
    assert "12 of the 13 frames" in err.problem


def test_frames_says_fewer_than_present(walk) -> None:
    err = _error(walk.text.replace("Frames: 12", "Frames: 10"))
    assert err.line == _frame_line(walk.text, 10)
    assert "more frame lines than 'Frames: 10'" in err.problem


@pytest.mark.parametrize(
    ("frames", "problem"),
    [
        ("Frames: 0", "no frames"),
        ("Frames: -3", "not a whole number of frames"),
        ("Frames: 2.5", "not a whole number of frames"),
        ("Frames: ²", "not a whole number of frames"),
        ("Frames:", "not a whole number of frames"),
        ("Frame: 12", "expected 'Frames: ...'"),
    ],
)
def test_bad_frame_count(walk, frames: str, problem: str) -> None:
    err = _error(walk.text.replace("Frames: 12", frames))
    assert err.line == _line_of(walk.text, "Frames:")
    assert problem in err.problem


@pytest.mark.parametrize("frame_time", ["0", "-0.033", "0.0", "abc", "1e-300", "12", "nan"])
def test_bad_frame_time(walk, frame_time: str) -> None:
    err = _error(walk.text.replace("Frame Time: 0.03333333", f"Frame Time: {frame_time}"))
    assert err.line == _line_of(walk.text, "Frame Time:")
    assert "frame time" in err.problem


def test_missing_frame_time_line(walk) -> None:
    text = walk.text.replace("Frame Time: 0.03333333\n", "")
    err = _error(text)
    assert err.line == _line_of(walk.text, "Frame Time:")
    assert "expected 'Frame Time: ...'" in err.problem


@pytest.mark.parametrize("data", ["", b"", "   \n\t\n  ", b"\r\n\r\n"])
def test_empty_or_whitespace_only_file(data: str | bytes) -> None:
    err = _error(data)
    assert "empty" in err.problem


def test_binary_file_with_nul_bytes_names_its_line(walk) -> None:
    data = walk.text.encode()
    at = data.index(b"JOINT LeftHip")
    err = _error(data[:at] + b"\x00\x01\x02" + data[at:])
    assert err.line == _line_of(walk.text, "JOINT LeftHip")
    assert "binary" in err.problem


def test_random_bytes_are_not_a_bvh_file() -> None:
    data = np.random.default_rng(7).integers(1, 256, 4000, dtype=np.uint8).tobytes()
    err = _error(data)
    assert "not UTF-8" in err.problem or "binary" in err.problem


def test_latin1_text_names_the_line_of_the_bad_byte(walk) -> None:
    data = walk.text.replace("JOINT LeftHip", "JOINT LeftHüft").encode("latin-1")
    err = _error(data)
    assert err.line == _line_of(walk.text, "JOINT LeftHip")
    assert "not UTF-8" in err.problem


def test_missing_motion_keyword_names_the_line_where_it_belongs(walk) -> None:
    err = _error(walk.text.replace("MOTION\n", ""))
    assert err.line == _line_of(walk.text, "MOTION")
    assert "expected ROOT or MOTION, found 'Frames:'" in err.problem


def test_hierarchy_without_motion_section(walk) -> None:
    text = walk.text[: walk.text.index("MOTION")]
    err = _error(text)
    assert err.line == text.rstrip().count("\n") + 1
    assert "no MOTION section" in err.problem


def test_text_that_is_not_bvh_at_all() -> None:
    err = _error("name,x,y\nhead,0,1\n")
    assert err.line == 1 and "HIERARCHY" in err.problem


def test_duplicate_joint_names_name_the_second_declaration(walk) -> None:
    text = walk.text.replace("JOINT RightElbow", "JOINT LeftElbow")
    err = _error(text)
    assert err.line == _line_of(walk.text, "JOINT RightElbow")
    assert "duplicate joint name 'LeftElbow'" in err.problem
    assert f"line {_line_of(walk.text, 'JOINT LeftElbow')}" in err.problem


@pytest.mark.parametrize(
    ("old", "new", "needle", "below", "problem"),
    [
        ("\t\t\t\t\tEnd Site\n", "\t\t\t\t\tEnd Thing\n", "End Site", 0, "expected 'Site'"),
        (
            "\t\t\t\t\t\tOFFSET 0.000000 0.160000 0.000000\n",
            "\t\t\t\t\t\tOFFSET 0.000000 0.160000 0.000000\n CHANNELS 1 Xrotation\n",
            "OFFSET 0.000000 0.160000",
            1,
            "End Site cannot have CHANNELS",
        ),
        # the name is missing, so '{' on the next line is read as the name
        ("JOINT Spine", "JOINT", "JOINT Spine", 1, "without a name"),
        ("JOINT Spine", "BONE Spine", "JOINT Spine", 0, "unexpected 'BONE' in joint Hips"),
        ("ROOT Hips", "JOINT Hips", "ROOT Hips", 0, "expected ROOT"),
        ("HIERARCHY", "HIERARCHIE", "HIERARCHY", 0, "expected 'HIERARCHY'"),
    ],
)
def test_malformed_hierarchy(
    walk, old: str, new: str, needle: str, below: int, problem: str
) -> None:
    err = _error(walk.text.replace(old, new, 1))
    assert err.line == _line_of(walk.text, needle) + below
    assert problem in err.problem


def test_extra_closing_brace_names_its_line(walk) -> None:
    text = walk.text.replace("}\nMOTION", "}\n}\nMOTION")
    err = _error(text)
    assert err.line == _line_of(walk.text, "MOTION")
    assert "expected ROOT or MOTION, found '}'" in err.problem


def test_unreadable_paths(tmp_path: Path) -> None:
    for path in (tmp_path, tmp_path / "missing.bvh"):
        with pytest.raises(BvhError) as info:
            read_bvh(path)
        assert str(info.value).startswith(f"{path}: cannot read file")
        with pytest.raises(BvhError) as info:
            load_bvh_take(path)
        assert str(info.value).startswith(f"{path}: cannot read file")


@pytest.mark.parametrize(
    ("frame_time", "fps"),
    [("0.0166670", 60.0), ("0.0083333", 120.0), (".0333333", 30.0), ("0.0172", 1 / 0.0172)],
)
def test_a_frame_rate_within_a_hundredth_of_a_percent_of_a_whole_number_is_that_number(
    walk, frame_time: str, fps: float
) -> None:
    """Frame times written to 7 decimals (0.0166670 s: 59.9988 fps) read as the whole rate
    they stand for, so exports keep it (USD timeCodesPerSecond 60, not 59.9988); a rate
    farther from a whole number (58.14) stays as written."""
    header = next(x for x in walk.text.splitlines() if x.startswith("Frame Time"))
    text = walk.text.replace(header, f"Frame Time: {frame_time}")
    assert parse_bvh(text).fps == pytest.approx(fps, rel=1e-12)
