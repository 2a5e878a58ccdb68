"""BVH import normalisation: units, up axis, floor, handedness, resampling, skipped frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bvh_fixtures import LEG_LENGTH, HumanoidFixture, make_humanoid

from samba.body.skeleton import JOINT_INDEX, bone_lengths
from samba.body.take import Take
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.ingest.errors import BvhError
from samba.ingest.normalize import UNITS, leading_tpose_frames, leg_length

HEAD, FEET = JOINT_INDEX["head"], [JOINT_INDEX["l_foot"], JOINT_INDEX["r_foot"]]
ATOL = 2e-5
"""Meters: six-decimal BVH numbers and float32 poses."""


def _load(
    tmp_path: Path, fixture: HumanoidFixture, options: BvhImportOptions | None = None
) -> Take:
    """Write the fixture to a file and import it."""
    path = tmp_path / "take.bvh"
    path.write_text(fixture.text)
    return load_bvh_take(path, options)


def _feet_on_floor(take: Take) -> None:
    """The lower foot touches y = 0 (within 1 cm) in every frame; no foot goes below."""
    lower = take.poses[:, FEET, 1].min(axis=1)
    assert np.abs(lower).max() < 0.01


def _spine_axis(text: str) -> str:
    """The axis along which the spine's rest OFFSET points ('x', 'y' or 'z')."""
    line = next(ln for ln in text.split("\n") if "OFFSET" in ln and ln.startswith("\t\t"))
    values = np.abs([float(v) for v in line.split()[1:]])
    return "xyz"[int(np.argmax(values))]


@pytest.mark.parametrize(
    ("unit", "scale"),
    [("m", 1.0), ("cm", 100.0), ("mm", 1000.0), ("in", 1 / 0.0254), ("cmu", 0.45 / 0.0254)],
)
def test_units_are_detected(tmp_path: Path, unit: str, scale: float) -> None:
    fixture = make_humanoid(frames=20, unit_scale=scale, seed=1)
    assert fixture.leg == pytest.approx(LEG_LENGTH * scale)
    take = _load(tmp_path, fixture)
    assert take.meta["units"] == unit
    assert leg_length(take.poses) == pytest.approx(LEG_LENGTH, rel=1e-5)
    np.testing.assert_allclose(take.poses, fixture.positions, atol=ATOL)
    assert take.warnings == []
    _feet_on_floor(take)


def test_units_override_scales_and_warns_about_an_implausible_leg(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=20, unit_scale=100.0)
    take = _load(tmp_path, fixture, BvhImportOptions(units="m"))
    assert take.meta["units"] == "m"
    assert leg_length(take.poses) == pytest.approx(LEG_LENGTH * 100, rel=1e-5)
    assert any("leg length 85.00 m is implausible" in w for w in take.warnings)


def test_units_override_that_agrees_with_detection_changes_nothing(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=20, unit_scale=1000.0)
    auto = _load(tmp_path, fixture)
    forced = _load(tmp_path, fixture, BvhImportOptions(units="mm", up="+y"))
    np.testing.assert_array_equal(auto.poses, forced.poses)
    assert forced.meta["units"] == "mm" and forced.meta["up"] == "+y"


@pytest.mark.parametrize("scale", [1.0, 100.0])
def test_z_up_file_is_detected_and_turned_to_y_up(tmp_path: Path, scale: float) -> None:
    fixture = make_humanoid(frames=20, up="+z", unit_scale=scale, seed=4)
    assert _spine_axis(fixture.text) == "z"
    take = _load(tmp_path, fixture)
    assert take.meta["up"] == "+z"
    assert (take.poses[:, HEAD, 1] > take.poses[:, FEET, 1].max(axis=1) + 1.0).all()
    np.testing.assert_allclose(take.poses, fixture.positions, atol=ATOL)
    assert take.warnings == []
    _feet_on_floor(take)


def test_up_override_is_used_as_given(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=20, up="+z")
    forced = _load(tmp_path, fixture, BvhImportOptions(up="+z"))
    np.testing.assert_allclose(forced.poses, fixture.positions, atol=ATOL)
    wrong = _load(tmp_path, fixture, BvhImportOptions(up="+y"))
    assert wrong.meta["up"] == "+y"
    head_above = wrong.poses[:, HEAD, 1] - wrong.poses[:, FEET, 1].mean(axis=1)
    assert np.abs(head_above).max() < 0.5  # the subject now lies on the floor


@pytest.mark.parametrize("up", ["+y", "+z"])
def test_mirrored_recording_is_detected_and_mirrored_back(tmp_path: Path, up: str) -> None:
    fixture = make_humanoid(frames=20, mirror=True, up=up)
    take = _load(tmp_path, fixture)
    assert take.meta["handedness"] == "left"
    assert len(take.warnings) == 1 and "mirrored X" in take.warnings[0]
    np.testing.assert_allclose(take.poses, fixture.positions, atol=ATOL)
    # the left hip ends up on the subject's left, +X for a subject facing +Z
    assert (take.poses[:, JOINT_INDEX["l_hip"], 0] > take.poses[:, JOINT_INDEX["r_hip"], 0]).all()


def test_handedness_right_keeps_a_mirrored_recording(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=20, mirror=True)
    take = _load(tmp_path, fixture, BvhImportOptions(handedness="right"))
    assert take.meta["handedness"] == "right"
    assert take.warnings == []
    np.testing.assert_allclose(take.poses, fixture.positions * [-1, 1, 1], atol=ATOL)


def test_right_handed_recording_is_kept_and_left_forces_a_mirror(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=20)
    auto = _load(tmp_path, fixture)
    assert auto.meta["handedness"] == "right"
    forced = _load(tmp_path, fixture, BvhImportOptions(handedness="left"))
    assert forced.meta["handedness"] == "left"
    np.testing.assert_allclose(forced.poses, fixture.positions * [-1, 1, 1], atol=ATOL)


def test_feet_touch_the_floor_after_import(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=60, unit_scale=100.0, up="+z", mirror=True, seed=9)
    take = _load(tmp_path, fixture)
    _feet_on_floor(take)
    assert float(take.meta["floor_tilt_deg"]) == pytest.approx(0.0, abs=0.01)


def test_feet_of_a_fixed_root_file_never_sink_below_the_floor(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=60, root_position_channels=False, seed=2)
    take = _load(tmp_path, fixture)
    lower = take.poses[:, FEET, 1].min(axis=1)
    assert lower.min() > -0.01
    assert np.percentile(lower, 5) == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize(("source_fps", "step"), [(120.0, 4), (60.0, 2), (30.0, 1)])
def test_integer_rate_ratios_pick_frames_exactly(
    tmp_path: Path, source_fps: float, step: int
) -> None:
    fixture = make_humanoid(frames=121, fps=source_fps, seed=6)
    take = _load(tmp_path, fixture, BvhImportOptions(fps=30.0))
    assert take.fps == 30.0
    assert take.meta["source_fps"] == f"{source_fps:.3f}"
    assert take.source_frames == 121
    assert len(take) == 120 // step + 1
    np.testing.assert_array_equal(take.frames, np.arange(len(take)))
    np.testing.assert_allclose(take.poses, fixture.positions[::step], atol=ATOL)


def test_resampling_50_to_30_fps_keeps_bone_lengths(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=51, fps=50.0, seed=2)
    take = _load(tmp_path, fixture, BvhImportOptions(fps=30.0))
    assert len(take) == 31
    reference = bone_lengths(fixture.positions[0])
    np.testing.assert_allclose(
        bone_lengths(take.poses.astype(np.float64)), np.broadcast_to(reference, (31, 8)), rtol=1e-6
    )


def test_resampling_50_to_30_fps_samples_the_right_times(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=51, fps=50.0, seed=2)
    take = _load(tmp_path, fixture, BvhImportOptions(fps=30.0))
    # output frame 3k is source frame 5k exactly, up to the common floor shift
    shift = take.poses[::3] - fixture.positions[::5]
    np.testing.assert_allclose(shift[..., [0, 2]], 0.0, atol=ATOL)
    assert np.ptp(shift[..., 1]) < 2 * ATOL and np.abs(shift[..., 1]).max() < 1e-3
    # the frames between follow the same motion sampled at 150 fps (the fixture's motion
    # is a function of time), to within the interpolation error
    truth = make_humanoid(frames=151, fps=150.0, seed=2).positions[::5]
    np.testing.assert_allclose(take.poses, truth, atol=2e-3)


def test_skip_frames_drops_leading_source_frames(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=121, fps=120.0, seed=3)
    take = _load(tmp_path, fixture, BvhImportOptions(fps=30.0, skip_frames=2))
    assert len(take) == 30
    np.testing.assert_allclose(take.poses, fixture.positions[2::4], atol=ATOL)
    same_rate = _load(tmp_path, fixture, BvhImportOptions(fps=120.0, skip_frames=7))
    np.testing.assert_allclose(same_rate.poses, fixture.positions[7:], atol=ATOL)
    assert same_rate.source_frames == 121


def test_skip_frames_dropping_everything_is_an_error(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=10)
    with pytest.raises(BvhError) as info:
        _load(tmp_path, fixture, BvhImportOptions(skip_frames=10))
    assert str(info.value).startswith(f"{tmp_path / 'take.bvh'}: --skip-frames 10 drops all 10")


def test_leading_tpose_is_kept_with_a_warning(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=30, tpose_frames=2, seed=8)
    assert leading_tpose_frames(fixture.positions) == 2
    take = _load(tmp_path, fixture)
    assert len(take) == 30
    assert take.warnings == ["starts with 2 T-pose frame(s) (0.07 s); --skip-tpose drops them"]
    np.testing.assert_allclose(take.poses, fixture.positions, atol=ATOL)


def test_skip_tpose_drops_the_leading_tpose(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=30, tpose_frames=2, seed=8)
    take = _load(tmp_path, fixture, BvhImportOptions(skip_tpose=True))
    assert len(take) == 28
    assert take.warnings == []
    np.testing.assert_allclose(take.poses, fixture.positions[2:], atol=ATOL)
    np.testing.assert_array_equal(take.frames, np.arange(2, 30))  # numbered from the source


def test_skip_tpose_without_a_tpose_keeps_every_frame(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=30)
    take = _load(tmp_path, fixture, BvhImportOptions(skip_tpose=True))
    assert len(take) == 30


@pytest.mark.parametrize("frames", [1, 2, 3])
def test_very_short_files_import(tmp_path: Path, frames: int) -> None:
    fixture = make_humanoid(frames=frames, seed=4)
    take = _load(tmp_path, fixture)
    assert len(take) == frames
    np.testing.assert_allclose(take.poses, fixture.positions, atol=ATOL)


def test_absurdly_large_values_are_an_error_not_a_crash(tmp_path: Path) -> None:
    fixture = make_humanoid(frames=5)
    lines = fixture.text.split("\n")
    first = lines.index("Frame Time: 0.03333333") + 1
    lines[first] = "1e300 " + lines[first].split(" ", 1)[1]
    path = tmp_path / "huge.bvh"
    path.write_text("\n".join(lines))
    with pytest.raises(BvhError) as info:
        load_bvh_take(path)
    assert str(info.value).startswith(f"{path}: joint positions reach 1e+300")


@pytest.mark.parametrize(
    ("options", "flag"),
    [
        ({"fps": 0}, "--fps"),
        ({"fps": -30}, "--fps"),
        ({"fps": float("nan")}, "--fps"),
        ({"fps": float("inf")}, "--fps"),
        ({"skip_frames": -1}, "--skip-frames"),
        ({"units": "furlong"}, "--units"),
        ({"units": "CM"}, "--units"),
        ({"up": "y"}, "--up"),
        ({"up": "+w"}, "--up"),
        ({"handedness": "ambidextrous"}, "--handedness"),
    ],
)
def test_options_reject_bad_values(options: dict[str, object], flag: str) -> None:
    with pytest.raises(ValueError, match=flag):
        BvhImportOptions(**options)  # type: ignore[arg-type]


def test_every_unit_and_axis_is_accepted() -> None:
    for unit in UNITS:
        assert BvhImportOptions(units=unit).units == unit
    for up in ("+x", "-x", "+y", "-y", "+z", "-z"):
        assert BvhImportOptions(up=up).up == up
