"""Whether corners found in an image can be a board's: the plausibility check of board
detection (`samba.cameras.calibration_board`).

A board is flat, so a camera without lens distortion sees its corners through a
homography, a projective map of the board's plane; a lens bends them only a little
over a board. The check fits that homography from the corners' board-plane positions
to their pixels by plain least squares (every corner weighs the same, so a wrong corner
shows as a large residual instead of being set aside as RANSAC would) and refuses the
grid when:

- a corner lies farther from the homography's image of it than `MAX_OFF_SPACING` times
  the corner spacing (the smallest distance, in pixels, between the homography's images
  of two neighbouring corners found), or `MIN_LIMIT_PX`, whichever is larger: a wrongly
  numbered or misplaced corner is off by a sizeable part of a square;
- the homography sends some corners behind the camera (the grid crosses its horizon);
- a cell of four neighbouring corners is turned over relative to the others, or has no
  area: the grid folds over itself.

Measured on 13 hand-held phone photos of a 4 x 7 checkerboard (1088 x 1920, corner
spacing 53-141 px, a lens with k1 = -0.05): every detected grid within 1.0 px of its
homography, under 0.01 of its spacing; the wrong grids OpenCV's exhaustive detector
returned on two of them (in some runs, before it was seeded) were 176-352 px
off. A lens simulated with k1 = -0.35 (a wide webcam) keeps a 4 x 7 board within 0.18 of
its spacing wherever it fits in the image; a larger board filling such an image can
exceed the limit and is refused (`samba calibrate -v` says so).
"""

from __future__ import annotations

import cv2
import numpy as np

MAX_OFF_SPACING = 0.25
"""Largest distance of a corner from the homography, as a fraction of the corner spacing."""
MIN_LIMIT_PX = 2.0
"""The limit on a corner's distance from the homography is never below this, pixels."""
NOT_PROJECTIVE = "corner grid not a projective image of the board"
"""How a refused grid is described, followed by the measurement in parentheses."""


def grid_problem(board_xy: np.ndarray, ids: np.ndarray, pixels: np.ndarray, columns: int) -> str:
    """Why corners found in an image cannot be the board's (see the module docstring),
    or "" when they can.

    `board_xy` (n, 2) are the board-plane positions (meters) of all n corners, indexed by
    id, laid out in rows of `columns` corners; `ids` (k,) the found corners' ids (k >= 4)
    and `pixels` (k, 2) their image positions, pixels.
    """
    ids = np.asarray(ids, dtype=np.int64)
    source = np.asarray(board_xy, dtype=np.float64)[ids]
    pixels = np.asarray(pixels, dtype=np.float64)
    homography, _ = cv2.findHomography(source, pixels, method=0)
    if homography is None or not np.isfinite(homography).all():
        return f"{NOT_PROJECTIVE} (no homography fits it)"
    depth = np.c_[source, np.ones(len(source))] @ homography[2]
    if not (np.all(depth > 0) or np.all(depth < 0)):
        return f"{NOT_PROJECTIVE} (it crosses the horizon of its homography)"
    predicted = _mapped(homography, source)
    off = float(np.linalg.norm(predicted - pixels, axis=1).max())
    square = float(np.linalg.norm(board_xy[1] - board_xy[0]))
    spacing = min(
        np.linalg.norm(_mapped(homography, source + step) - predicted, axis=1).min()
        for step in ([square, 0.0], [0.0, square])
    )
    limit = max(MIN_LIMIT_PX, MAX_OFF_SPACING * float(spacing))
    if off > limit:
        return f"{NOT_PROJECTIVE} (max {off:.1f} px off a homography; {limit:.1f} px allowed)"
    areas = _cell_areas(ids, pixels, columns)
    if len(areas) and not (np.all(areas > 0) or np.all(areas < 0)):
        return f"{NOT_PROJECTIVE} (the grid folds over itself)"
    return ""


def _mapped(homography: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Plane points (k, 2) through a (3, 3) homography, (k, 2)."""
    return cv2.perspectiveTransform(points.reshape(1, -1, 2), homography)[0]


def _cell_areas(ids: np.ndarray, pixels: np.ndarray, columns: int) -> np.ndarray:
    """Signed image areas (c,), px^2, of the c cells whose four corners were all found
    (corner id, the next in its row, and the two below them), each traced the same way
    round on the board."""
    where = {int(i): p for i, p in zip(ids, pixels, strict=True)}
    areas = []
    for i in where:
        quad = [i, i + 1, i + 1 + columns, i + columns]
        if (i + 1) % columns == 0 or not all(q in where for q in quad):
            continue
        x, y = np.array([where[q] for q in quad]).T
        areas.append(0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
    return np.array(areas)
