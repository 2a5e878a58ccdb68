"""What every Samba package stands on: the error types a user sees (`SambaError`,
`InputError`: one line naming the input and the problem), atomic file writes, the
command-line argument types the `samba` subcommands share, the rule they write outputs
by (`check_outputs`: never over a file without `--force`, never over an input), and
numba kernels compiled once per install (`KernelSet`, `compiled`, `kernels_enabled`).
Batch commands run on a Dask cluster through `cluster_client` and `outcomes_in_order`.
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
from samba.base.cluster import (
    WorkerDeathError,
    add_cluster_arguments,
    cluster_client,
    outcomes_in_order,
)
from samba.base.compiled_kernels import KernelSet, compiled, kernels_enabled, usable_cores
from samba.base.errors import InputError, SambaError
from samba.base.output_files import FORCE_HINT, add_force_argument, check_outputs

__all__ = [
    "FORCE_HINT",
    "InputError",
    "KernelSet",
    "SambaError",
    "WorkerDeathError",
    "add_cluster_arguments",
    "add_force_argument",
    "address",
    "atomic_path",
    "bind_address",
    "check_outputs",
    "cluster_client",
    "compiled",
    "finite_float",
    "kernels_enabled",
    "natural",
    "outcomes_in_order",
    "positive",
    "positive_float",
    "seconds_range",
    "usable_cores",
    "write_bytes_atomic",
    "write_text_atomic",
]
