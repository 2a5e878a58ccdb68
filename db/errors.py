"""Errors raised by the pose store and its index."""

from samba.base import InputError, SambaError


class StoreError(InputError):
    """A store directory is missing, locked, damaged, or asked for something it lacks."""


class QueryError(InputError):
    """A nearest-pose query is malformed (wrong shape, no markers, bad k)."""


class StoreCorruptedError(SambaError):
    """`verify` found damage; the message lists every problem found."""
