"""OpenCV's checkerboard detectors, in the order `Board.find` tries them
(`samba.cameras.calibration_board`).

1. "sb": `cv2.findChessboardCornersSB` with CALIB_CB_NORMALIZE_IMAGE (equalises the
   image first; finds boards in unevenly lit photos that the plain call misses);
2. "sb-exhaustive": the same with CALIB_CB_EXHAUSTIVE as well (a wider search: tilted
   boards partly cut by the frame edge; it can also return a wrong grid, which the
   plausibility check of `samba.cameras.corner_grid` refuses);
3. "classic": `cv2.findChessboardCorners` with CALIB_CB_ADAPTIVE_THRESH |
   CALIB_CB_NORMALIZE_IMAGE, on the image downscaled to at most `CLASSIC_MAX_SIDE`
   pixels for speed, corners scaled back.

Each returns the inner corners, unrefined, in OpenCV's order (rows of `columns`); the
caller refines them (`cv2.cornerSubPix`), checks and numbers them. The order is one of
accuracy and speed: on the shared phone photos (../shared/data/pose2sim) the lens solved
from the "sb" corners as returned fits them within 0.15 px (RMS), from the classic ones
within 0.94-1.15 px (both 0.21-0.23 px after `cornerSubPix`). CALIB_CB_ACCURACY is not
used: it takes 3-7 times as long, and after `cornerSubPix` its corners give the same
lens within 0.01%.
"""

from __future__ import annotations

import cv2
import numpy as np

SB_SEED = 0
"""`findChessboardCornersSB` samples from OpenCV's global random generator, so that the
same image can give a right grid on one run and a wrong one on the next (the exhaustive
search on two of the shared phone photos: 1-2 wrong grids in 8 runs each). The generator
is seeded with this before every call: a detection is the same on every run."""
CHECKERBOARD_DETECTORS = ("sb", "sb-exhaustive", "classic")
"""The detectors `checkerboard_corners` knows, in the order `Board.find` tries them."""
CLASSIC_MAX_SIDE = 2000
"""The classic detector looks at the image downscaled to at most this width and height,
pixels (a 1920 x 1080 frame as it is, a 4032 x 3024 photo at half size)."""
_SB_FLAGS = {
    "sb": cv2.CALIB_CB_NORMALIZE_IMAGE,
    "sb-exhaustive": cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE,
}
_CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE


def checkerboard_corners(
    grey: np.ndarray, grid: tuple[int, int], detector: str
) -> np.ndarray | None:
    """The (columns x rows, 2) inner corners, pixels, of a checkerboard of `grid`
    (columns, rows) inner corners found by `detector` (one of `CHECKERBOARD_DETECTORS`)
    in a grey (h, w) uint8 image, or None when it finds none. The "sb" detectors reseed
    OpenCV's global random generator (`SB_SEED`)."""
    if detector in _SB_FLAGS:
        cv2.setRNGSeed(SB_SEED)
        found, corners = cv2.findChessboardCornersSB(grey, grid, flags=_SB_FLAGS[detector])
        return corners.reshape(-1, 2).astype(np.float64) if found else None
    if detector != "classic":
        raise ValueError(f"detector must be one of {CHECKERBOARD_DETECTORS}, got {detector!r}")
    scale = min(1.0, CLASSIC_MAX_SIDE / max(grey.shape))
    small = grey
    if scale < 1.0:
        small = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    found, corners = cv2.findChessboardCorners(small, grid, flags=_CLASSIC_FLAGS)
    if not found:
        return None
    # Pixel centres sit at integer coordinates: scale about the image's corner at -0.5.
    return (corners.reshape(-1, 2).astype(np.float64) + 0.5) / scale - 0.5
