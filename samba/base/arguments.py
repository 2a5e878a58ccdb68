"""Argument types the `samba` subcommands share: argparse reports their errors (exit 2)."""

from __future__ import annotations

import argparse
import math


def natural(text: str) -> int:
    """An integer >= 0 from a command-line word."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def positive(text: str) -> int:
    """An integer >= 1 from a command-line word."""
    value = natural(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def finite_float(text: str) -> float:
    """A finite number from a command-line word."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text}")
    return value


def positive_float(text: str) -> float:
    """A finite number > 0 from a command-line word (a frame rate, a length)."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return value


def seconds_range(text: str) -> tuple[float, float]:
    """(start, stop) seconds from an `A:B` word, 0 <= A < B (a stretch of a take)."""
    start_text, sep, stop_text = text.partition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected START:STOP in seconds, got {text!r}")
    start, stop = finite_float(start_text), finite_float(stop_text)
    if not 0 <= start < stop:
        raise argparse.ArgumentTypeError(f"need 0 <= START < STOP, got {text!r}")
    return start, stop


def address(text: str) -> tuple[str, int]:
    """(host, port) from a `HOST:PORT` word (IPv4 address or host name, port 1..65535)."""
    return _host_port(text, lowest_port=1)


def bind_address(text: str) -> tuple[str, int]:
    """(host, port) to listen on from a `HOST:PORT` word; port 0 = any free port."""
    return _host_port(text, lowest_port=0)


def _host_port(text: str, lowest_port: int) -> tuple[str, int]:
    host, sep, port_text = text.rpartition(":")
    if not sep or not host:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, got {text!r}")
    try:
        port = int(port_text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"port is not an integer in {text!r}") from None
    if not lowest_port <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port must be {lowest_port}..65535 in {text!r}")
    return host, port
