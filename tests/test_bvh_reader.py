"""The BVH motion reader's compiled kernel (`samba.ingest.kernels.motion_table_kernel`,
through `samba.ingest.motion_table.read_table`) reads the same float64 bits as its reference,
`np.loadtxt`, on every shared CMU file and on crafted text; what it cannot read goes to
`np.loadtxt` and the diagnosis, which still name the offending line."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

import samba.ingest.motion_table as motion_table
from samba.base import kernels_enabled
from samba.body import resample_times
from samba.ingest.bvh import SampleTimes, parse_bvh
from samba.ingest.errors import BvhError
from samba.ingest.motion_table import read_table

pytestmark = pytest.mark.skipif(
    not kernels_enabled(), reason="numba kernels are off (SAMBA_KERNELS=numpy or no numba)"
)

HEADER = """HIERARCHY
ROOT hips
{
  OFFSET 0 0 0
  CHANNELS 3 Xposition Yposition Zposition
  End Site
  {
    OFFSET 0 1 0
  }
}
MOTION
"""
"""A one-joint hierarchy of three channels: frames are rows of three numbers."""


def loadtxt(text: bytes) -> np.ndarray:
    """The reference: `np.loadtxt` of the frame lines, as the reader called it before."""
    return np.loadtxt(io.StringIO(text.decode()), dtype=np.float64, ndmin=2, comments=None)


def kernel(text: bytes, frames: int, columns: int) -> np.ndarray | None:
    """The kernel's table of `text`, or None where it leaves the text to `np.loadtxt`."""
    return read_table(np.frombuffer(text, dtype=np.uint8), frames, columns)


def assert_same_bits(got: np.ndarray, want: np.ndarray) -> None:
    """Equal shapes and float64 bit patterns (so -0.0 and 0.0 differ)."""
    assert got.shape == want.shape
    np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))


def motion_body(data: bytes) -> bytes:
    """The frame lines of a BVH file: everything after its 'Frame Time:' line."""
    start = data.index(b"Frame Time")
    return data[data.index(b"\n", start) + 1 :]


def test_every_shared_cmu_file_reads_as_loadtxt_reads_it(
    cmu_files: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_fallback(body: str) -> None:
        raise AssertionError("the kernel gave the file up to np.loadtxt")

    monkeypatch.setattr(motion_table, "_read_numbers", no_fallback)
    for path in cmu_files:
        data = path.read_bytes()
        want = loadtxt(motion_body(data))
        assert_same_bits(parse_bvh(data, source=str(path)).motion, want)


NUMBERS = [
    "0",
    "-0",
    "-0.0",
    "+1.5",
    ".5",
    "-.25",
    "5.",
    "007.250",
    "1e5",
    "1E+5",
    "2.5e-3",
    "3.88251e-19",
    "-3.88251e-19",
    "1e22",
    "1e23",
    "1e-22",
    "1e-23",
    "9007199254740991",
    "9007199254740993",
    "123456789012345678901234567890",
    "0.1234567890123456789",
    "0.000000000000000000000000001",
    "1.7976931348623157e308",
    "4.9e-324",
    "2e-400",
    "0e99999999",
    "1e0000000000000000003",
    "-0.12345678901234567890123456789012345678901234567890",  # beyond the gathered width
    "1234567890123456789012345678901234567890.5e-30",
]
"""Forms of numbers and the edges of the exact one-operation conversion (10^22, 2^53)."""


def test_every_number_form_reads_to_the_same_bits() -> None:
    text = "\n".join(f"{v} 1 {v}" for v in NUMBERS).encode()
    assert_same_bits(kernel(text, len(NUMBERS), 3), loadtxt(text))


def random_numbers(n: int, seed: int, formats: list[str]) -> str:
    """n random numbers of magnitudes 1e-12 to 1e12, printed in turn in `formats`, six a
    line."""
    rng = np.random.default_rng(seed)
    values = (rng.standard_normal(n) * 10.0 ** rng.integers(-12, 12, n)).tolist()
    tokens = [formats[i % len(formats)].format(v) for i, v in enumerate(values)]
    return "\n".join(" ".join(tokens[i : i + 6]) for i in range(0, n, 6))


def test_random_numbers_printed_every_way_read_to_the_same_bits() -> None:
    formats = ["{:.6f}", "{:.4f}", "{:g}", "{:.6e}", "{:.15g}", "{:.3E}", "{:.8f}", "{!r}"]
    text = random_numbers(6000, 7, formats).encode()
    assert_same_bits(kernel(text, 1000, 6), loadtxt(text))


def test_a_file_of_full_precision_numbers_goes_to_loadtxt_and_reads_the_same() -> None:
    text = random_numbers(600, 8, ["{!r}"]).encode()
    assert kernel(text, 100, 6) is None  # every number needs Python's float: loadtxt is as fast
    rows = random_numbers(300, 8, ["{!r}"]).replace(" ", "\n").split("\n")
    body = "\n".join(" ".join(rows[i : i + 3]) for i in range(0, 300, 3))
    data = frames_text(body.split("\n")).encode()
    assert_same_bits(parse_bvh(data).motion, loadtxt(motion_body(data)))


@pytest.mark.parametrize(
    "text",
    [
        b"1 2 3\r\n4 5 6\r\n",  # CRLF
        b"1\t2\t3\n4\t 5 \t6",  # tabs, no final line end
        b"1 2 3   \n4 5 6 \t \n",  # trailing spaces
        b"1 2 3\n4 5 6\n\n\n  \n\t\n",  # blank trailing lines
        b"\n\n1 2 3\n\n4 5 6\n",  # blank lines before and between
        b"   1 2 3\n  4 5 6\n",  # leading spaces
        b"1 2 3\r\n\r\n4 5 6\r\n\r\n",  # CRLF blank lines
    ],
)
def test_line_ends_and_blanks_read_as_loadtxt_reads_them(text: bytes) -> None:
    assert_same_bits(kernel(text, 2, 3), loadtxt(text))


@pytest.mark.parametrize(
    "text",
    [
        b"1 2 nan\n4 5 6\n",
        b"1 2 inf\n4 5 6\n",
        b"1 2 -Infinity\n",
        b"1 2 3 # a comment\n",
        b"1 2 x\n",
        b"1 2 1e\n",
        b"1 2 1.2.3\n",
        b"1 2 -\n",
        b"1 2 .\n",
        b"1 2 0x10\n",
        b"1 2 1_000\n",
        b"1 2 3\x0b\n",
        "1 2 3\u00a0\n".encode(),
    ],
)
def test_what_is_no_plain_number_is_left_to_loadtxt(text: bytes) -> None:
    assert kernel(text, 1, 3) is None


@pytest.mark.parametrize(
    ("text", "frames"),
    [
        (b"1 2 3\n4 5\n", 2),  # a short row
        (b"1 2 3 4\n4 5 6\n", 2),  # a long row
        (b"1 2 3\n4 5 6\n7 8 9\n", 2),  # more rows than frames
        (b"1 2 3\n", 2),  # fewer rows than frames
    ],
)
def test_rows_of_the_wrong_length_or_too_many_are_left_to_the_diagnosis(
    text: bytes, frames: int
) -> None:
    assert kernel(text, frames, 3) is None


def frames_text(rows: list[str], line_end: str = "\n") -> str:
    """A whole file of the one-joint hierarchy with `rows` as its frames."""
    head = HEADER + f"Frames: {len(rows)}\nFrame Time: 0.01\n"
    return (head + "\n".join(rows) + "\n").replace("\n", line_end)


@pytest.mark.parametrize("line_end", ["\n", "\r\n"])
@pytest.mark.parametrize(
    ("bad_row", "problem"),
    [
        ("1 2", "frame 40 has 2 values, the hierarchy declares 3 channels"),
        ("1 2 3 4", "frame 40 has 4 values, the hierarchy declares 3 channels"),
        ("1 2 zero", "frame 40: 'zero' is not a number"),
        ("1 nan 3", "frame 40 holds NaN or infinity"),
        ("1 1e999 3", "frame 40 holds NaN or infinity"),
    ],
)
def test_a_bad_row_is_still_named_by_its_line(line_end: str, bad_row: str, problem: str) -> None:
    rows = [f"{i} {i}.5 -{i}e-3" for i in range(80)]
    rows[40] = bad_row
    text = frames_text(rows, line_end)
    with pytest.raises(BvhError) as info:
        parse_bvh(text.encode(), source="bad.bvh")
    assert info.value.problem == problem
    assert info.value.line == HEADER.count("\n") + 3 + 40


def test_a_frames_count_that_disagrees_with_the_rows_is_still_diagnosed() -> None:
    rows = [f"{i} 0 0" for i in range(5)]
    more = frames_text(rows).replace("Frames: 5", "Frames: 4").encode()
    with pytest.raises(BvhError, match="more frame lines than 'Frames: 4' declares"):
        parse_bvh(more)
    fewer = frames_text(rows).replace("Frames: 5", "Frames: 6").encode()
    with pytest.raises(BvhError, match="file ends after 5 of the 6 frames"):
        parse_bvh(fewer)


def test_a_frames_count_far_beyond_the_text_is_diagnosed_without_reserving_it() -> None:
    rows = [f"{i} 0 0" for i in range(5)]
    huge = frames_text(rows).replace("Frames: 5", "Frames: 4000000000000").encode()
    with pytest.raises(BvhError, match="file ends after 5 of the 4000000000000 frames"):
        parse_bvh(huge)


def test_bytes_text_and_a_byte_order_mark_read_the_same_numbers() -> None:
    rows = [f"{i / 7!r} {-i / 3:.6f} {i * 1e-20:e}" for i in range(50)]
    text = frames_text(rows)
    want = loadtxt(motion_body(text.encode()))
    crlf_and_cr = text.replace("\n", "\r\n", 3).replace("\n", "\r")  # 3 bytes shorter
    variants = [text, text.encode(), b"\xef\xbb\xbf" + text.encode(), text.replace("\n", "\r")]
    for data in [*variants, crlf_and_cr.encode()]:
        assert_same_bits(parse_bvh(data).motion, want)


def test_a_motion_header_across_the_first_window_reads_the_same() -> None:
    rows = [f"{i} {i}.25 -{i}e-3" for i in range(5)]
    text = frames_text(rows)
    want = parse_bvh(text).motion
    header_end = text.index("MOTION\n") + len("MOTION")
    for blank in range(4060, 4110, 3):  # 'Frame Time: 0.01' before, across and after byte 4096
        padded = text[:header_end] + "\n" * blank + text[header_end:]
        bvh = parse_bvh(padded.encode())
        assert bvh.frame_time == 0.01
        assert_same_bits(bvh.motion, want)


def test_with_kernels_off_the_reader_reads_the_same_numbers(
    cmu_files: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    data = cmu_files[0].read_bytes()
    compiled = parse_bvh(data).motion
    monkeypatch.setenv("SAMBA_KERNELS", "numpy")
    assert_same_bits(parse_bvh(data).motion, compiled)


@pytest.mark.parametrize("value", ["1e308", "-2e7"])
def test_an_offset_beyond_10_km_in_millimetres_is_named_with_its_line(value: str) -> None:
    text = (
        HEADER.replace("OFFSET 0 1 0", f"OFFSET 0 {value} 0")
        + "Frames: 1\nFrame Time: 0.1\n0 0 0\n"
    )
    with pytest.raises(BvhError, match=r":8: OFFSET of hips_end: .* is out of range"):
        parse_bvh(text)


def sample_every(step: float) -> SampleTimes:
    """A `parse_bvh` sample of every `step`-th frame (fractional steps interpolate)."""
    return lambda frames, fps: np.arange(0.0, frames - 1, step)


def test_a_file_read_for_some_frames_holds_their_rows_as_read_whole(
    cmu_files: list[Path],
) -> None:
    for path in cmu_files[::7]:
        data = path.read_bytes()
        whole = parse_bvh(data, source=str(path))
        some = parse_bvh(data, source=str(path), sample=sample_every(3.7))
        assert some.n_frames == whole.n_frames
        assert some.held[0] == 0 and len(some.held) < whole.n_frames / 1.8
        assert_same_bits(some.motion, whole.motion[some.held])
        times = np.arange(0.0, whole.n_frames - 1, 3.7)
        joints = [0, len(whole.joints) - 1]
        assert_same_bits(
            some.sampled_positions(joints, times), whole.sampled_positions(joints, times)
        )
        with pytest.raises(ValueError, match="frame 2 was not read"):
            some.sampled_positions(joints, np.array([2.0]))


@pytest.mark.parametrize(
    ("bad_row", "problem"),
    [
        ("1 2", "frame 41 has 2 values, the hierarchy declares 3 channels"),
        ("1 2 3 4", "frame 41 has 4 values, the hierarchy declares 3 channels"),
        ("1 2 zero", "frame 41: 'zero' is not a number"),
        ("1 nan 3", "frame 41 holds NaN or infinity"),
    ],
)
def test_a_bad_row_among_the_frames_not_converted_is_named_by_its_line(
    bad_row: str, problem: str
) -> None:
    rows = [f"{i} {i}.5 -{i}e-3" for i in range(80)]
    rows[41] = bad_row
    some = sample_every(4.0)  # frames 0, 4, ..., 40, 44: 41 is only checked
    with pytest.raises(BvhError) as info:
        parse_bvh(frames_text(rows).encode(), source="bad.bvh", sample=some)
    assert info.value.problem == problem
    assert info.value.line == HEADER.count("\n") + 3 + 41


@pytest.mark.parametrize("fps", [30.0, 24.0, 7.5])
def test_compiled_positions_agree_with_the_numpy_path_to_1e_9_m(
    cmu_files: list[Path], monkeypatch: pytest.MonkeyPatch, fps: float
) -> None:
    for path in cmu_files[::6]:  # the three rigs, position channels on their roots
        bvh = parse_bvh(path.read_bytes(), source=str(path))
        joints = list(range(0, len(bvh.joints), 2))
        times = resample_times(bvh.n_frames, bvh.fps, fps)
        compiled = bvh.sampled_positions(joints, times)
        with monkeypatch.context() as numpy_only:
            numpy_only.setenv("SAMBA_KERNELS", "numpy")
            reference = bvh.sampled_positions(joints, times)
        # file units (centimetres, inches): 1e-9 of them is under 1e-9 m
        np.testing.assert_allclose(compiled, reference, rtol=0, atol=1e-9)
