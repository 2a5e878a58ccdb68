"""A live session's subject calibration: the skin offsets of the subject's markers,
calibrated from the session's first seconds and removed from every frame after.

A marker session with `calibrate_s` > 0 collects the triangulated markers of its first
frames that can be reconstructed (`calibrate_s` seconds at the session's frame rate),
then calibrates the offsets (`samba.reconstruct.calibrate_skin_offsets`) in a
background thread, so the frames go on meanwhile (reconstructed from the raw markers).
From the frame after it finishes, each frame's markers are moved to their joints with
the segment frames of the pose the previous estimates predict, as
`SkinMarkerReconstructor.step` does, and the offsets go with every frame's output so
that the session stores them with its takes.
"""

from __future__ import annotations

import logging
import threading

import numpy as np

from samba.reconstruct import Reconstructor, SkinOffsets, calibrate_skin_offsets

LOG = logging.getLogger("samba.service")


class SubjectCalibration:
    """Collects `frames` usable frames of markers for `reconstructor`'s subject, then
    calibrates its skin offsets in the background; `offsets` is None until done."""

    def __init__(self, reconstructor: Reconstructor, frames: int, session: str) -> None:
        self.reconstructor = reconstructor
        self.frames = frames
        self.session = session
        self.offsets: SkinOffsets | None = None
        self._collected: list[np.ndarray] = []
        self._thread: threading.Thread | None = None

    def joints(self, markers: np.ndarray) -> np.ndarray:
        """One frame's markers (8, 3) world meters (NaN = missing) moved to their joints
        once the offsets are known (the raw markers before); collects the frame for the
        calibration until it has enough."""
        if self.offsets is not None:
            guess = self.reconstructor.prediction()
            if guess is not None:
                return self.offsets.joints(markers[None], guess[None])[0]
            return markers
        if self._thread is None:
            present = ~np.isnan(markers).any(axis=-1)
            if self.reconstructor.usable(present[None])[0]:
                self._collected.append(np.array(markers, dtype=np.float64))
            if len(self._collected) >= self.frames:
                self._thread = threading.Thread(
                    target=self._calibrate, name=f"calibrate-{self.session}", daemon=True
                )
                self._thread.start()
        return markers

    def wait(self, timeout: float | None = None) -> bool:
        """Wait for a started calibration to finish; whether the offsets are known."""
        if self._thread is not None:
            self._thread.join(timeout)
        return self.offsets is not None

    def _calibrate(self) -> None:
        markers = np.stack(self._collected)
        try:
            offsets = calibrate_skin_offsets(self.reconstructor, markers)
        except ValueError as exc:  # no frame usable after all: keep the raw markers
            LOG.warning("session %s: subject calibration failed: %s", self.session, exc)
            return
        LOG.info(
            "session %s: subject calibrated from %d frames:\n%s",
            self.session,
            len(markers),
            offsets.report(),
        )
        self.offsets = offsets
