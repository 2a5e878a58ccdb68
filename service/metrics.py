"""A capture session's running figures: latency percentiles over its recent frames and
how its markers were labelled."""

from __future__ import annotations

import numpy as np

PERCENTILES: tuple[float, ...] = (50.0, 90.0, 99.0)
"""Latency percentiles reported by `LatencyWindow.summary`."""


class LatencyWindow:
    """The last `size` latencies in a ring buffer, for percentiles over recent frames.

    Values are seconds in, milliseconds out; memory is fixed (`size` float64).
    """

    def __init__(self, size: int = 4096) -> None:
        if size < 1:
            raise ValueError(f"a latency window holds at least one value, got size {size}")
        self._values = np.empty(size)
        self._next = 0
        self.count = 0
        """Latencies added since the start (not only those still in the window)."""

    def add(self, seconds: float) -> None:
        """Record one latency in seconds."""
        self._values[self._next] = seconds
        self._next = (self._next + 1) % len(self._values)
        self.count += 1

    def values_ms(self) -> np.ndarray:
        """The latencies in the window, milliseconds, oldest first (n,) float64."""
        n = min(self.count, len(self._values))
        if n < len(self._values):
            return self._values[:n] * 1e3
        return np.roll(self._values, -self._next) * 1e3

    def summary(self) -> dict[str, float | int | None]:
        """`count` (all time), `window` (values summarised), mean, p50, p90, p99 and max in
        milliseconds over the window; the statistics are None before any value."""
        values = self.values_ms()
        out: dict[str, float | int | None] = {"count": self.count, "window": len(values)}
        stats = {"mean_ms": np.mean, "max_ms": np.max}
        for name, statistic in stats.items():
            out[name] = round(float(statistic(values)), 3) if len(values) else None
        for p in PERCENTILES:
            value = float(np.percentile(values, p)) if len(values) else None
            out[f"p{p:g}_ms"] = None if value is None else round(value, 3)
        return out


class LabelCounts:
    """How a marker session's markers were labelled, counted over its frames out, one
    count per marker of every camera that sent the frame: `from_nodes` the labels the
    nodes sent, `found_by_server` the ones the nodes had lost that the server's labelling
    found again (`labels` "server"), `missing` the ones still missing after labelling;
    and `subject_found_again`, the frames in which the server's labelling found the
    subject again in the standard pose after losing it entirely."""

    def __init__(self) -> None:
        self.from_nodes = 0
        self.found_by_server = 0
        self.missing = 0
        self.subject_found_again = 0

    def add(self, sent: np.ndarray, labelled: np.ndarray, found_again: bool = False) -> None:
        """Count one frame: the labels `sent` (c, 8, 2) pixels, NaN = lost, by the c
        cameras whose packets came, the same cameras' `labelled` (c, 8, 2) ones that were
        triangulated, and whether the subject was `found_again` in it."""
        node = ~np.isnan(sent).any(axis=-1)
        out = ~np.isnan(labelled).any(axis=-1)
        self.from_nodes += int(node.sum())
        self.found_by_server += int((out & ~node).sum())
        self.missing += int((~out).sum())
        self.subject_found_again += int(found_again)

    def summary(self) -> dict[str, int]:
        """The four counts by name."""
        return {
            "from_nodes": self.from_nodes,
            "found_by_server": self.found_by_server,
            "missing": self.missing,
            "subject_found_again": self.subject_found_again,
        }
