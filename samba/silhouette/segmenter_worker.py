"""The person segmenter's worker process. It runs in the segmenter's own Python
environment (MediaPipe 0.10.21, which needs numpy < 2), never in Samba's: it imports
nothing of Samba. `samba.silhouette.person_segmentation` starts one per video.

MediaPipe Pose (BlazePose, model complexity 1, tracking across frames) finds the most
prominent person and gives its segmentation mask. Protocol on the binary standard
streams: the worker writes `READY\\n`; then per frame it reads a header of two
little-endian uint32 (height, width) and height * width * 3 bytes of BGR pixels, and
writes height * width bytes of mask (255: the person, 0: not). A header of zeros, or the
end of its input, ends it.
"""

import struct
import sys

import cv2
import mediapipe as mp
import numpy as np

THRESHOLD = 0.5
"""Mask probability above which a pixel is the person."""


def main() -> None:
    source, sink = sys.stdin.buffer, sys.stdout.buffer
    pose = mp.solutions.pose.Pose(
        static_image_mode=False,
        model_complexity=1,
        enable_segmentation=True,
        smooth_segmentation=True,
    )
    sink.write(b"READY\n")
    sink.flush()
    while True:
        header = source.read(8)
        if len(header) < 8:
            return
        height, width = struct.unpack("<II", header)
        if height == 0 or width == 0:
            return
        pixels = source.read(height * width * 3)
        if len(pixels) < height * width * 3:
            return
        frame = np.frombuffer(pixels, dtype=np.uint8).reshape(height, width, 3)
        found = pose.process(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)).segmentation_mask
        mask = np.zeros((height, width), dtype=np.uint8)
        if found is not None:
            mask[found > THRESHOLD] = 255
        sink.write(mask.tobytes())
        sink.flush()


if __name__ == "__main__":
    main()
