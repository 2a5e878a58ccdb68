"""Property tests: mangled BVH files either import or raise a `SambaError` naming the file.

Each example mutates a valid fixture file (lines deleted, duplicated or swapped, the text
truncated, tokens replaced, unicode or raw bytes inserted, channel and frame counts
changed) and feeds it to `parse_bvh` and `load_bvh_take`. Anything but a clean result
or a `SambaError` whose message starts with the source name fails.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from bvh_fixtures import make_humanoid
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from samba.base.errors import SambaError
from samba.ingest.bvh import BvhFile, parse_bvh
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take

pytestmark = pytest.mark.filterwarnings("error")  # a warning is output the user sees, too

SOURCE = "fuzz.bvh"
BASES: tuple[str, ...] = tuple(
    fixture.text
    for fixture in (
        make_humanoid("cmu-max", frames=4, extra_joints=False),
        make_humanoid("daz", frames=3, unit_scale=100.0, channel_order=["XYZ", "YZX"]),
        make_humanoid("mixamo", frames=3, up="+z", line_ending="\r\n", number_format=".4e"),
        make_humanoid("iclone", frames=5, fps=60.0, root_position_channels=False, indent="  "),
    )
)
"""Valid files to mangle: four rigs, units, axes, channel orders and formats."""
_TOKEN = re.compile(r"\S+")
SETTINGS = settings(
    max_examples=300,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

numbers = st.one_of(
    st.integers(-(10**30), 10**30).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["1e308", "-1.7976931348623157e308", "1e-320", "1e999", "0", "-0", "1e9"]),
)
replacements = st.one_of(
    numbers,
    st.sampled_from(
        ["nan", "-inf", "{", "}", "", "²", "ROOT", "JOINT", "End", "Site", "MOTION", "CHANNELS"]
    ),
    st.sampled_from(["OFFSET", "Frames:", "Frame Time:", "Xposition", "Zrotation", "\n", "\r"]),
    st.text(max_size=12),
)


@st.composite
def line_edit(draw: st.DrawFn, text: str) -> str:
    """Delete, duplicate or swap lines."""
    lines = text.split("\n")
    i = draw(st.integers(0, len(lines) - 1))
    j = draw(st.integers(0, len(lines) - 1))
    kind = draw(st.sampled_from(["delete", "duplicate", "swap"]))
    if kind == "delete":
        del lines[i]
    elif kind == "duplicate":
        lines.insert(j, lines[i])
    else:
        lines[i], lines[j] = lines[j], lines[i]
    return "\n".join(lines)


@st.composite
def token_edit(draw: st.DrawFn, text: str) -> str:
    """Replace one whitespace-separated token by a random string, number or keyword."""
    tokens = list(_TOKEN.finditer(text))
    if not tokens:
        return draw(replacements)
    m = tokens[draw(st.integers(0, len(tokens) - 1))]
    return text[: m.start()] + draw(replacements) + text[m.end() :]


@st.composite
def motion_edit(draw: st.DrawFn, text: str) -> str:
    """Replace one value of the motion data by a random (possibly extreme) number."""
    start = text.find("Frame Time:")
    tokens = list(_TOKEN.finditer(text, start + 12)) if start >= 0 else []
    if not tokens:
        return text
    m = tokens[draw(st.integers(0, len(tokens) - 1))]
    return text[: m.start()] + draw(numbers) + text[m.end() :]


@st.composite
def count_edit(draw: st.DrawFn, text: str) -> str:
    """Change one CHANNELS count or the Frames: count."""
    counts = list(re.finditer(r"(CHANNELS |Frames: )(\d+)", text))
    if not counts:
        return text
    m = counts[draw(st.integers(0, len(counts) - 1))]
    value = draw(st.one_of(st.integers(0, 12), st.integers(0, 10**12)))
    return text[: m.start(2)] + str(value) + text[m.end(2) :]


@st.composite
def insert_text(draw: st.DrawFn, text: str) -> str:
    """Insert random unicode text at a random offset."""
    at = draw(st.integers(0, len(text)))
    return text[:at] + draw(st.text(min_size=1, max_size=8)) + text[at:]


@st.composite
def truncate(draw: st.DrawFn, text: str) -> str:
    """Cut the text at a random offset."""
    return text[: draw(st.integers(0, len(text)))]


EDITS = (line_edit, token_edit, motion_edit, motion_edit, count_edit, insert_text, truncate)


@st.composite
def mangled(draw: st.DrawFn) -> bytes:
    """A fixture file after one to three random edits, possibly with raw bytes inserted."""
    text = draw(st.sampled_from(BASES))
    for _ in range(draw(st.integers(1, 3))):
        text = draw(draw(st.sampled_from(EDITS))(text))
    data = text.encode("utf-8", errors="surrogatepass")
    if draw(st.integers(0, 3)) == 0:
        at = draw(st.integers(0, len(data)))
        data = data[:at] + draw(st.binary(min_size=1, max_size=6)) + data[at:]
    return data


def _check_parsed(bvh: BvhFile) -> None:
    """A successful parse holds finite numbers consistent with its hierarchy."""
    assert np.isfinite(bvh.motion).all()
    assert all(np.isfinite(j.offset).all() for j in bvh.joints)
    assert bvh.motion.shape[1] == sum(len(j.channels) for j in bvh.joints)
    assert 0 < bvh.frame_time < 10 and bvh.n_frames > 0


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder for the files `load_bvh_take` reads."""
    return tmp_path_factory.mktemp("fuzz")


@pytest.mark.slow
@SETTINGS
@given(data=mangled())
def test_parse_bvh_succeeds_or_raises_a_samba_error(data: bytes) -> None:
    try:
        bvh = parse_bvh(data, source=SOURCE)
    except SambaError as exc:
        assert str(exc).startswith(f"{SOURCE}:")
    else:
        _check_parsed(bvh)


@SETTINGS
@given(data=mangled())
def test_parse_bvh_of_str_succeeds_or_raises_a_samba_error(data: bytes) -> None:
    text = data.decode("utf-8", errors="replace")
    try:
        bvh = parse_bvh(text, source=SOURCE)
    except SambaError as exc:
        assert str(exc).startswith(f"{SOURCE}:")
    else:
        _check_parsed(bvh)


@SETTINGS
@given(data=mangled(), fps=st.sampled_from([30.0, 24.0, 120.0]))
def test_load_bvh_take_succeeds_or_raises_a_samba_error(
    fuzz_dir: Path, data: bytes, fps: float
) -> None:
    path = fuzz_dir / "fuzz.bvh"
    path.write_bytes(data)
    try:
        take = load_bvh_take(path, BvhImportOptions(fps=fps))
    except SambaError as exc:
        assert str(exc).startswith(f"{path}:")
    else:
        assert take.poses.shape[1:] == (13, 3) and len(take) > 0
        assert np.isfinite(take.poses).all()
        assert take.fps == fps


@settings(max_examples=200, deadline=None)
@given(text=st.sampled_from(BASES), cut=st.floats(0.0, 1.0))
def test_truncated_files_fail_naming_their_last_line(text: str, cut: float) -> None:
    cut_text = text[: int(cut * text.rstrip().rindex(" "))]  # up to before the last value
    with pytest.raises(SambaError) as info:
        parse_bvh(cut_text, source=SOURCE)
    assert str(info.value).startswith(f"{SOURCE}:")
    if cut_text.strip():
        assert info.value.line == cut_text.rstrip().count("\n") + 1  # type: ignore[attr-defined]
