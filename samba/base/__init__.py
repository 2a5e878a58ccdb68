"""What every Samba package stands on: the error types a user sees (`SambaError`,
`InputError`: one line naming the input and the problem), atomic file writes, and the
command-line argument types the `samba` subcommands share.
"""

from samba.base.arguments import (
    address,
    bind_address,
    finite_float,
    natural,
    positive,
    positive_float,
    seconds_range,
)
from samba.base.atomic_file import atomic_path, write_bytes_atomic, write_text_atomic
from samba.base.errors import InputError, SambaError

__all__ = [
    "InputError",
    "SambaError",
    "address",
    "atomic_path",
    "bind_address",
    "finite_float",
    "natural",
    "positive",
    "positive_float",
    "seconds_range",
    "write_bytes_atomic",
    "write_text_atomic",
]
