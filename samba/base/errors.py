"""The project's exception hierarchy.

Every error a user can cause (a bad file, a bad flag, a bad query) is a `SambaError`
subclass whose message names the input and what is wrong. The command line prints
these without a traceback and exits non-zero; anything else escaping is a bug.
"""


class SambaError(Exception):
    """Base class of every error Samba raises on purpose."""


class InputError(SambaError):
    """A file or value given by the user is malformed.

    `source` names the input (a path or a flag), `line` is the 1-based line number in
    that input when one applies.
    """

    def __init__(self, source: str, problem: str, line: int | None = None) -> None:
        self.source = source
        self.problem = problem
        self.line = line
        where = f"{source}:{line}" if line is not None else source
        super().__init__(f"{where}: {problem}")

    def __reduce__(self) -> tuple[type, tuple[str, str, int | None]]:
        """Pickle by the constructor's arguments, so that the error crosses a process
        boundary (a Dask worker's task) as it was raised."""
        return type(self), (self.source, self.problem, self.line)
