"""`SessionPolicy`: what a session started over the control API may name.

`POST /api/sessions` takes a session table from whoever holds the token. Without limits
it could make the server open any file (and say whether it exists), or send VMC to any
host and port. A session started over the API may therefore only name:

- files and folders (`calibration`, `database`, `avatar`) given to the server at start
  (its sessions' own), or under a folder the server was told the API may use
  (`samba serve --api-files DIR`), after following symbolic links;
- VMC receivers given to the server at start, or allowed with `--api-vmc HOST:PORT`;

and the server runs at most `max_sessions` sessions (`--max-sessions`). Takes are
written only under the server's takes folder: a session's name is its sub-folder
(`SESSION_NAME` allows no `.`, `..` or hidden name).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from samba.service.errors import ServiceError
from samba.service.session_config import SessionConfig

DEFAULT_MAX_SESSIONS = 8
"""Most sessions a server runs unless told otherwise."""


class SessionPolicy:
    """The paths and VMC receivers API sessions may name, and the most sessions; see the
    module docstring. `files`: paths given at start; `folders`: folders whose contents
    the API may name; `vmc`: (host, port) receivers; `max_sessions` >= 1."""

    def __init__(
        self,
        files: Iterable[Path] = (),
        folders: Iterable[Path] = (),
        vmc: Iterable[tuple[str, int]] = (),
        max_sessions: int = DEFAULT_MAX_SESSIONS,
    ) -> None:
        if isinstance(max_sessions, bool) or not isinstance(max_sessions, int) or max_sessions < 1:
            raise ValueError(f"max_sessions {max_sessions!r} is not an integer >= 1")
        self._files = {Path(f).resolve() for f in files}
        self._folders = [Path(f).resolve() for f in folders]
        self._vmc = set(vmc)
        self.max_sessions = max_sessions

    @classmethod
    def of(
        cls,
        configs: Iterable[SessionConfig],
        folders: Iterable[Path] = (),
        vmc: Iterable[tuple[str, int]] = (),
        max_sessions: int = DEFAULT_MAX_SESSIONS,
    ) -> SessionPolicy:
        """The policy of a server started with `configs`: their files and VMC receivers,
        with `folders` and `vmc` allowed besides."""
        configs = list(configs)
        files = [p for c in configs for p in (c.calibration, c.database, c.avatar) if p]
        targets = [t for c in configs for t in c.vmc]
        return cls(files, folders, [*targets, *vmc], max_sessions)

    def check(self, config: SessionConfig, source: str = "request body") -> None:
        """`ServiceError` naming `source` and the key when `config` names a path or VMC
        receiver this server may not use for an API session; nothing is opened."""
        for key in ("calibration", "database", "avatar"):
            path = getattr(config, key)
            if path is not None and not self.allows_path(path):
                raise ServiceError(
                    source,
                    f"{key} {str(path)[:80]!r} is not a path this server may open for the API: "
                    "name one given at its start or under an --api-files folder",
                )
        for host, port in config.vmc:
            if (host, port) not in self._vmc:
                raise ServiceError(
                    source,
                    f"vmc {host[:80]}:{port} is not a receiver this server may send to for the "
                    "API: name one given at its start or with --api-vmc",
                )

    def allows_path(self, path: Path) -> bool:
        """Whether `path` (relative: to the working folder) is a file given at start or
        lies under an allowed folder, once symbolic links are followed."""
        try:
            resolved = path.resolve()
        except (OSError, RuntimeError, ValueError):  # a link loop, a NUL in the name
            return False
        return resolved in self._files or any(resolved.is_relative_to(f) for f in self._folders)
