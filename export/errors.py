"""Errors raised while exporting takes: bad avatars, unknown takes, unwritable outputs."""

from samba.base import InputError


class ExportError(InputError):
    """An export cannot be made: the message names the input (take, avatar file, output
    path or flag) and what is wrong with it."""
