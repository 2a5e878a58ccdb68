"""Errors raised by the live capture service on bad input, such as an unreadable take file."""

from samba.base import InputError


class ServiceError(InputError):
    """A file or value given to the service is unusable: the message names it and the problem."""


class PacketError(InputError):
    """A camera-node packet the server drops: `reason` says why, `source` names the sender.

    `reason` is one of `REASONS`, a small fixed set the server counts drops by; the
    message adds the details (which field, which value).
    """

    REASONS: tuple[str, ...] = (
        "too short",
        "too long",
        "bad magic",
        "unsupported version",
        "bad length",
        "missing tag",
        "no key",
        "bad tag",
        "unexpected tag",
        "bad values",
    )

    def __init__(self, source: str, reason: str, detail: str = "") -> None:
        if reason not in self.REASONS:
            raise ValueError(f"unknown packet error reason {reason!r}")
        self.reason = reason
        super().__init__(source, f"{reason}: {detail}" if detail else reason)
