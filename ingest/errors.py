"""Errors raised while reading and mapping foreign motion files."""

from samba.base import InputError


class BvhError(InputError):
    """A BVH file is malformed: the message names the file, the line and the problem."""


class RigError(InputError):
    """A skeleton cannot be mapped to the 13 joints, or a mapping file is invalid."""


class TakeFileError(InputError):
    """A recorded take (.mcap) cannot be read: the message names the file and the problem."""


class C3dError(InputError):
    """A C3D marker file cannot be read, or its labels cannot give the 8 markers: the
    message names the file and the problem."""
