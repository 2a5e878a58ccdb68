"""Marker pixels a camera cannot have seen: those outside its image.

A node reports pixels of its own camera's image. A value outside it (a stray 3e38 px
in a forged or broken packet) would otherwise be triangulated into a point tens of
meters away and recorded; `keep_inside` makes such markers missing and drops such
blobs, and the session counts them (`markers_outside`, `blobs_outside` in its metrics).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from samba.cameras import Camera
from samba.service.packet import MarkerPacket


def keep_inside(packet: MarkerPacket, camera: Camera) -> tuple[MarkerPacket, int, int]:
    """`packet` with its markers outside `camera`'s image made missing (NaN) and its
    blobs outside dropped (`Camera.in_image`: pixel centres, -0.5..size - 0.5 px), and
    how many markers and blobs that was; the packet itself when all are inside."""
    present = ~np.isnan(packet.markers[:, 0])
    outside = present & ~camera.in_image(packet.markers)
    blobs_in = camera.in_image(packet.blobs)
    markers_dropped, blobs_dropped = int(outside.sum()), int((~blobs_in).sum())
    if not markers_dropped and not blobs_dropped:
        return packet, 0, 0
    markers = packet.markers.copy()
    markers[outside] = np.nan
    return (
        replace(packet, markers=markers, blobs=packet.blobs[blobs_in]),
        markers_dropped,
        blobs_dropped,
    )
