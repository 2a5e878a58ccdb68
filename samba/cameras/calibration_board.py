"""Calibration boards: their geometry, their look, and finding their corners in an image.

A board is a flat checkerboard or ChArUco board (OpenCV's layouts). Its frame has the
origin at the first corner point (a checkerboard's first inner corner; a ChArUco
board's outer corner, as in OpenCV), x along the rows of corners, y down the columns,
z into the board (a camera that sees the printed face is on the -z side), meters.

Corner ids number the corner points row by row: a checkerboard of `columns` x `rows`
inner corners has ids 0 .. columns * rows - 1; a ChArUco board of `columns` x `rows`
squares has (columns - 1) x (rows - 1) inner corners, which its markers identify.

A plain checkerboard looks the same after a half turn unless its two sides differ in
colour, so its spec must have one even and one odd count of inner corners: then the
square diagonally outside corner 0 is black and the one outside the last corner white,
and `Board.detect` numbers the corners so that corner 0 is next to the black outer
square in every view and every camera.

Detection (`Board.find`) tries OpenCV's detectors in order of accuracy until one finds a
board that passes the checks: for a checkerboard "sb", "sb-exhaustive" and "classic"
(`samba.cameras.checkerboard_detectors`), for a ChArUco board "charuco"
(`cv2.aruco.CharucoDetector`, which accepts a partial board: at least
`MIN_CHARUCO_CORNERS` corners). The corners are refined with `cv2.cornerSubPix` in a
window scaled to the corner spacing (kept inside the white margin around ChArUco
markers), then refused unless they are a plausible projective image of the board
(`samba.cameras.corner_grid`), so that no detector's wrong grid reaches a solve. The
`Detection` says which detector found the board, or why none did. On the rendered
boards of the tests the corners land within about 0.05 px (RMS) of the truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from scipy.spatial.distance import pdist

from samba.base import InputError
from samba.cameras.checkerboard_detectors import CHECKERBOARD_DETECTORS, checkerboard_corners
from samba.cameras.corner_grid import grid_problem

KINDS = ("checkerboard", "charuco")
"""The board kinds `parse_board` accepts."""
BOARD_SPEC_HELP = (
    "checkerboard:COLSxROWS:SQUARE (inner corners, square side in meters, e.g. "
    "checkerboard:9x6:0.04) or charuco:COLSxROWS:SQUARE:MARKER:DICT (squares, sides in "
    "meters, an OpenCV ArUco dictionary, e.g. charuco:7x5:0.08:0.06:4X4_50)"
)
"""What a `--board` spec looks like."""
MIN_CHARUCO_CORNERS = 6
"""ChArUco corners a view needs to count as a detection."""
MIN_ORIENTATION_VOTE = 0.5
"""Net share of neighbouring inner squares that must agree on which way round a
checkerboard is (1: all of them; 0.5: three in four)."""
NOT_FOUND = "no board found"
"""What a detector that found nothing reports."""
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)


@dataclass(frozen=True)
class BoardView:
    """The corners of a board found in one image: `ids` (k,) int corner ids, ascending,
    `pixels` (k, 2) their sub-pixel image positions (OpenCV pixel convention), and the
    `detector` that found them ("" when not known)."""

    ids: np.ndarray
    pixels: np.ndarray
    detector: str = ""


@dataclass(frozen=True)
class Detection:
    """What looking for a board in one image came to: its `view` (None when no detector
    found it) and the `attempts`, in order: (detector, "" when it found the board, else
    why not, e.g. "no board found" or "rejected: ...")."""

    view: BoardView | None
    attempts: tuple[tuple[str, str], ...]

    @property
    def summary(self) -> str:
        """One line: the detector that found the board, or why none did, with the grids
        refused on the way, e.g. "classic (sb-exhaustive rejected: corner grid not a
        projective image of the board (max 218.5 px off a homography; 26.9 px allowed))"."""
        refused = [(name, why) for name, why in self.attempts if why and why != NOT_FOUND]
        if self.view is not None:
            notes = "; ".join(f"{name} {why}" for name, why in refused)
            return self.view.detector + (f" ({notes})" if notes else "")
        if not refused:
            return NOT_FOUND
        return "; ".join(f"{why} ({name})" for name, why in refused)


@dataclass(frozen=True)
class Board:
    """A calibration board. `kind` is "checkerboard" or "charuco"; `columns` x `rows`
    counts a checkerboard's inner corners or a ChArUco board's squares; `square` is
    the side of a square and `marker` that of a ChArUco marker, meters; `dictionary`
    is a ChArUco board's ArUco dictionary name without "DICT_" (e.g. "4X4_50")."""

    kind: str
    columns: int
    rows: int
    square: float
    marker: float = 0.0
    dictionary: str = ""

    def __post_init__(self) -> None:
        problem = self._problem()
        if problem:
            raise ValueError(f"board {self.spec}: {problem}")

    def _problem(self) -> str:
        """What is wrong with this board, or ""."""
        if self.kind not in KINDS:
            return f"kind must be one of {', '.join(KINDS)}"
        least = 3 if self.kind == "checkerboard" else 2
        if self.columns < least or self.rows < least:
            return f"needs at least {least}x{least} {self._counted}"
        if not (np.isfinite(self.square) and self.square > 0):
            return "the square side must be a positive number of meters"
        if self.kind == "checkerboard":
            if (self.columns + self.rows) % 2 == 0:
                return (
                    "a checkerboard needs one even and one odd count of inner corners "
                    "(e.g. 9x6) so that its orientation is unambiguous"
                )
            return ""
        if not (np.isfinite(self.marker) and 0 < self.marker < self.square):
            return "the marker side must be positive and smaller than the square side"
        if not hasattr(cv2.aruco, f"DICT_{self.dictionary}"):
            return f"unknown ArUco dictionary {self.dictionary!r} (e.g. 4X4_50, 5X5_100)"
        markers = self.columns * self.rows // 2
        available = self._dictionary.bytesList.shape[0]
        if markers > available:
            return f"needs {markers} markers but dictionary {self.dictionary} has {available}"
        return ""

    @property
    def _counted(self) -> str:
        return "inner corners" if self.kind == "checkerboard" else "squares"

    @property
    def spec(self) -> str:
        """The board as a `parse_board` spec."""
        base = f"{self.kind}:{self.columns}x{self.rows}:{self.square:g}"
        return base if self.kind == "checkerboard" else f"{base}:{self.marker:g}:{self.dictionary}"

    @property
    def corner_grid(self) -> tuple[int, int]:
        """(columns, rows) of the board's corner points."""
        if self.kind == "checkerboard":
            return self.columns, self.rows
        return self.columns - 1, self.rows - 1

    @cached_property
    def object_points(self) -> np.ndarray:
        """Board-frame positions (n, 3), meters, of the n corner points, indexed by id."""
        columns, rows = self.corner_grid
        first = 0.0 if self.kind == "checkerboard" else self.square
        ids = np.arange(columns * rows)
        points = np.zeros((len(ids), 3))
        points[:, 0] = first + self.square * (ids % columns)
        points[:, 1] = first + self.square * (ids // columns)
        points.flags.writeable = False
        return points

    @cached_property
    def _dictionary(self) -> cv2.aruco.Dictionary:
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, f"DICT_{self.dictionary}"))

    @cached_property
    def _charuco(self) -> cv2.aruco.CharucoBoard:
        return cv2.aruco.CharucoBoard(
            (self.columns, self.rows), self.square, self.marker, self._dictionary
        )

    def texture(self, pixels_per_square: int) -> tuple[np.ndarray, np.ndarray]:
        """The printable board: a grey uint8 image with a white margin of one square, and
        the (3, 3) matrix taking board-plane points (x, y, 1), meters, to its pixels.

        Checkerboard squares are black where (column + row) of the square is even, so
        the square diagonally outside corner 0 is black.
        """
        if pixels_per_square < 1:
            raise ValueError(f"pixels_per_square must be >= 1, got {pixels_per_square}")
        pps = int(pixels_per_square)
        if self.kind == "checkerboard":
            squares_x, squares_y = self.columns + 1, self.rows + 1
            cells = (np.add.outer(np.arange(squares_y), np.arange(squares_x)) % 2) * 255
            board = np.kron(cells, np.ones((pps, pps))).astype(np.uint8)
            image = np.pad(board, pps, constant_values=255)
            origin = 2 * pps  # corner 0 is one square in from the board's edge
        else:
            size = ((self.columns + 2) * pps, (self.rows + 2) * pps)
            image = self._charuco.generateImage(size, marginSize=pps)
            origin = pps  # the ChArUco frame's origin is the board's outer corner
        scale = pps / self.square
        # Pixel centres sit at integer coordinates: the edge at `origin` is origin - 0.5.
        to_pixels = np.array(
            [[scale, 0.0, origin - 0.5], [0.0, scale, origin - 0.5], [0.0, 0.0, 1.0]]
        )
        return image, to_pixels

    def detect(self, image: np.ndarray) -> BoardView | None:
        """The board's corners in a grey (h, w) or BGR (h, w, 3) uint8 image, or None
        (`find` says why)."""
        return self.find(image).view

    def find(self, image: np.ndarray) -> Detection:
        """Look for the board in a grey (h, w) or BGR (h, w, 3) uint8 image: its view, and
        which detector found it or why none did (module docstring).

        A checkerboard counts only when all its corners are found, numbered as the module
        docstring says; a ChArUco board when at least `MIN_CHARUCO_CORNERS` corners not
        all on one line are found (a partial board: the markers identify the corners).
        Either is refused when its corners fail the plausibility check of
        `samba.cameras.corner_grid`.
        """
        grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        if self.kind == "charuco":
            view, problem = self._charuco_view(grey)
            return Detection(view, (("charuco", problem),))
        attempts = []
        for detector in CHECKERBOARD_DETECTORS:
            view, problem = self._checkerboard_view(grey, detector)
            attempts.append((detector, problem))
            if view is not None:
                return Detection(view, tuple(attempts))
        return Detection(None, tuple(attempts))

    def _checkerboard_view(self, grey: np.ndarray, detector: str) -> tuple[BoardView | None, str]:
        """The checkerboard `detector` finds, refined, checked and numbered, or None and
        why not."""
        corners = checkerboard_corners(grey, self.corner_grid, detector)
        if corners is None:
            return None, NOT_FOUND
        ids = np.arange(len(corners))
        pixels = _refined(grey, corners, 1.0 / 3.0)
        problem = grid_problem(self.object_points[:, :2], ids, pixels, self.corner_grid[0])
        if problem:
            return None, f"rejected: {problem}"
        pixels, problem = self._oriented(grey, pixels)
        if pixels is None:
            return None, f"rejected: {problem}"
        return BoardView(ids=ids, pixels=pixels, detector=detector), ""

    def _oriented(self, grey: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray | None, str]:
        """Checkerboard corners (n, 2) reordered to the board's numbering (module
        docstring), or None and why when the squares' colours do not tell its sides apart.

        Seen from its printed face, the grid runs clockwise in the image (x along a row,
        then y down); a half turn is told from the colours of its inner squares: the one
        between corners (i, j) and (i + 1, j + 1) is black when i + j is even. Each pair of
        neighbouring squares votes by which is darker; at least `MIN_ORIENTATION_VOTE` of
        the votes (net) must agree.
        """
        columns, rows = self.corner_grid
        grid = pixels.reshape(rows, columns, 2)
        along, down = grid[0, 1] - grid[0, 0], grid[1, 0] - grid[0, 0]
        if along[0] * down[1] - along[1] * down[0] < 0:  # seen mirrored: x runs backwards
            grid = grid[:, ::-1]
        vote = _colour_vote(grey, grid)
        if not abs(vote) >= MIN_ORIENTATION_VOTE:
            return None, "the squares' colours do not say which way round the board is"
        if vote < 0:  # corner 0 is where the last should be: a half turn
            grid = grid[::-1, ::-1]
        return grid.reshape(-1, 2).copy(), ""

    def _charuco_view(self, grey: np.ndarray) -> tuple[BoardView | None, str]:
        """The ChArUco corners found, refined and checked, or None and why not."""
        corners, ids, _, _ = cv2.aruco.CharucoDetector(self._charuco).detectBoard(grey)
        if ids is None or len(ids) == 0:
            return None, NOT_FOUND
        if len(ids) < MIN_CHARUCO_CORNERS:
            return None, f"only {len(ids)} corners found; at least {MIN_CHARUCO_CORNERS} needed"
        ids = ids.ravel().astype(np.int64)
        order = np.argsort(ids)
        # The window must stay within the white margin around the markers.
        reach = min(1.0 / 3.0, 0.8 * (self.square - self.marker) / (2.0 * self.square))
        ids, pixels = ids[order], _refined(grey, corners.reshape(-1, 2)[order], reach)
        spread = np.linalg.svd(self.object_points[ids, :2] - self.object_points[ids, :2].mean(0))
        if spread.S[-1] < 0.5 * self.square:
            return None, "the corners found lie (nearly) on one line"
        problem = grid_problem(self.object_points[:, :2], ids, pixels, self.corner_grid[0])
        if problem:
            return None, f"rejected: {problem}"
        return BoardView(ids=ids, pixels=pixels, detector="charuco"), ""


def _refined(grey: np.ndarray, pixels: np.ndarray, reach: float) -> np.ndarray:
    """Corners (k, 2) refined by `cv2.cornerSubPix`, as float64, in a window reaching
    `reach` times the distance between the closest two corners from each corner (wide
    enough to see the corner, narrow enough to see nothing else)."""
    half = int(np.clip(reach * pdist(pixels).min(), 2, 11))
    corners = np.ascontiguousarray(pixels, dtype=np.float32).reshape(-1, 1, 2)
    corners = cv2.cornerSubPix(grey, corners, (half, half), (-1, -1), _SUBPIX_CRITERIA)
    return corners.reshape(-1, 2).astype(np.float64)


def _mean_around(grey: np.ndarray, point: np.ndarray, radius: int = 1) -> float | None:
    """Mean grey level of the (2 radius + 1)^2 pixels around `point`, None if outside."""
    u, v = np.round(point).astype(int)
    height, width = grey.shape
    if not (radius <= u < width - radius and radius <= v < height - radius):
        return None
    return float(grey[v - radius : v + radius + 1, u - radius : u + radius + 1].mean())


def _colour_vote(grey: np.ndarray, grid: np.ndarray) -> float:
    """How strongly (-1 .. 1) the inner squares of a checkerboard's corner grid (rows,
    columns, 2) say that the square between corners (i, j) and (i + 1, j + 1) is black
    when i + j is even (+1: every pair of neighbouring squares agrees; -1: every pair says
    the board is half turned; NaN when no pair can be measured)."""
    centres = (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:]) / 4.0
    spacing = min(
        np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
        np.linalg.norm(np.diff(grid, axis=1), axis=-1).min(),
    )
    radius = max(1, int(0.15 * spacing))
    levels = np.array(
        [[_mean_around(grey, c, radius) for c in row] for row in centres], dtype=np.float64
    )
    black = np.add.outer(np.arange(levels.shape[0]), np.arange(levels.shape[1])) % 2 == 0
    darker = np.where(black, -levels, levels)  # larger where the square is as expected
    pairs = np.concatenate(
        [
            (darker[:, :-1] + darker[:, 1:]).ravel(),
            (darker[:-1] + darker[1:]).ravel(),
        ]
    )
    pairs = pairs[np.isfinite(pairs)]
    return float(np.sign(pairs).mean()) if len(pairs) else float("nan")


def parse_board(spec: str) -> Board:
    """The `Board` of a spec such as "checkerboard:9x6:0.04" or
    "charuco:7x5:0.08:0.06:4X4_50" (see `BOARD_SPEC_HELP`); InputError("--board", ...)
    when it is malformed."""
    parts = spec.strip().split(":")
    kind = parts[0].lower()
    expected = {"checkerboard": 3, "charuco": 5}
    if kind not in expected or len(parts) != expected[kind]:
        raise InputError("--board", f"cannot read {spec!r}; expected {BOARD_SPEC_HELP}")
    try:
        columns, rows = (int(n) for n in parts[1].lower().split("x"))
        sizes = [float(part) for part in parts[2:4]]  # the square, and a ChArUco marker
    except ValueError:
        raise InputError("--board", f"cannot read {spec!r}; expected {BOARD_SPEC_HELP}") from None
    dictionary = parts[4].upper().removeprefix("DICT_") if kind == "charuco" else ""
    try:
        return Board(kind, columns, rows, *sizes, dictionary=dictionary)
    except ValueError as exc:
        raise InputError("--board", str(exc)) from None
