"""A writer process for the store crash tests, and the deterministic takes it writes.

    python tests/store_writer.py STORE MODE [--max-ops N] [--die-at POINT]

(with the project root on PYTHONPATH). MODE "import" adds takes 0, 1, 2, ...; MODE "mixed"
adds two takes, then removes the older one, and so on. The writer prints `ready` once
the store is open, finds where the store stands in the plan and goes on from there, so a
writer killed at any moment can simply be started again. `--die-at` makes it SIGKILL
itself at a chosen point of a write (see `DIE_POINTS`).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from samba.body.perturb import perturb_joint_angles
from samba.body.skeleton import Body
from samba.body.take import Take
from samba.db import store as store_module
from samba.db.store import INDEX, PoseStore

PLAN_LENGTH = 3000
DIE_POINTS = ("append", "compact", "index", "save")
"""append: pose rows written, catalog not committed; compact: compacted files written, not
committed; index: committed, index not yet rebuilt; save: new index written to its temp
file, not yet renamed over `index.npz`."""

Op = tuple[str, int]


def take_name(i: int) -> str:
    """The name of writer take i."""
    return f"take-{i:04d}"


def take_number(name: str) -> int:
    """The i of a writer take's name, or of its mirror's name."""
    return int(name.removeprefix("take-").split(" ")[0])


def is_mirrored(i: int) -> bool:
    """Whether take i is imported with its mirror."""
    return i % 3 == 0


def builds_index(i: int) -> bool:
    """Whether the import of take i rebuilds the index (otherwise it is left stale)."""
    return i % 2 == 0


def take_poses(i: int, n: int, seed: int) -> np.ndarray:
    """n float32 poses set by `seed`: perturbed A-poses of one body walking along a line."""
    rng = np.random.default_rng(seed)
    body = Body.from_height(float(rng.uniform(1.5, 1.9)))
    base = np.broadcast_to(body.standard_pose(float(rng.uniform(20, 70))), (n, 13, 3))
    poses = perturb_joint_angles(base, 12.0, rng)
    poses[:, :, 2] += np.linspace(0.0, 0.02 * n, n)[:, None]
    poses[:, :, 0] += i * 0.001  # the take's number, in its content
    return poses.astype(np.float32)


def writer_take(i: int) -> Take:
    """Writer take i: 8..30 poses whose content (and content hash) is set by i."""
    n = 8 + (i * 7) % 23
    return Take(
        name=take_name(i),
        poses=take_poses(i, n, seed=1000 + i),
        fps=30.0,
        source=f"test://writer/{i}",
        content_hash=f"writer-{i}",
        rig="test",
    )


def probe_take(k: int) -> Take:
    """Take k imported by the test process itself between writer runs."""
    return Take(
        name=f"probe-{k}",
        poses=take_poses(0, 6, seed=50_000 + k),
        fps=30.0,
        source=f"test://probe/{k}",
        content_hash=f"probe-{k}",
        rig="probe",
    )


def plan(mode: str, length: int = PLAN_LENGTH) -> list[Op]:
    """The writer's operations: ("add", i) or ("remove", i)."""
    if mode == "import":
        return [("add", i) for i in range(length)]
    if mode != "mixed":
        raise ValueError(f"unknown writer mode {mode!r}")
    ops: list[Op] = []
    added = 0
    while len(ops) < length:
        ops += [("add", added), ("add", added + 1), ("remove", added)]
        added += 2
    return ops[:length]


def plan_states(ops: list[Op]) -> list[frozenset[int]]:
    """The set of writer takes (originals) after each prefix of `ops`; [0] is the empty set."""
    states = [frozenset[int]()]
    for op, i in ops:
        states.append(states[-1] | {i} if op == "add" else states[-1] - {i})
    return states


def writer_takes_in(store: PoseStore) -> frozenset[int]:
    """The numbers of the writer takes (originals) in a store's snapshot."""
    return frozenset(
        take_number(t.name) for t in store.takes if t.name.startswith("take-") and not t.mirrored
    )


def plan_step(store: PoseStore, states: list[frozenset[int]]) -> int:
    """How many operations of the plan the store's snapshot reflects."""
    held = writer_takes_in(store)
    matches = [j for j, s in enumerate(states) if s == held]
    if not matches:
        raise AssertionError(f"writer takes {sorted(held)} are no state of the plan")
    return matches[-1]


def apply(store: PoseStore, op: Op) -> None:
    """Carry out one operation of the plan."""
    kind, i = op
    if kind == "add":
        store.add(writer_take(i), mirror=is_mirrored(i), build_index=builds_index(i))
    else:
        store.remove([take_name(i)])


def _die() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def _die_after(method: Callable[..., object]) -> Callable[..., object]:
    def wrapped(*args: object, **kwargs: object) -> object:
        method(*args, **kwargs)
        _die()
        return None

    return wrapped


def install_die_point(point: str) -> None:
    """Make this process SIGKILL itself the first time the write reaches `point`."""
    if point == "append":
        store_module.append_rows = _die_after(store_module.append_rows)
    elif point == "compact":
        store_module.write_compacted = _die_after(store_module.write_compacted)
    elif point == "index":
        PoseStore.build_index = lambda self: _die()  # type: ignore[method-assign,assignment,return-value]
    elif point == "save":
        replace = os.replace

        def replace_or_die(src: str | Path, dst: str | Path) -> None:
            if Path(dst).name == INDEX:
                _die()
            replace(src, dst)

        os.replace = replace_or_die  # PoseIndex.save renames its temp file with it
    else:
        raise ValueError(f"unknown die point {point!r}; one of {DIE_POINTS}")


def main(argv: list[str] | None = None) -> int:
    """Run the writer; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("store", type=Path)
    parser.add_argument("mode", choices=("import", "mixed"))
    parser.add_argument("--max-ops", type=int, default=None)
    parser.add_argument("--die-at", choices=DIE_POINTS, default=None)
    args = parser.parse_args(argv)
    if args.die_at:
        install_die_point(args.die_at)
    store = PoseStore.open(args.store)
    ops = plan(args.mode)
    start = plan_step(store, plan_states(ops))
    print("ready", start, flush=True)
    stop = len(ops) if args.max_ops is None else start + args.max_ops
    for op in ops[start:stop]:
        apply(store, op)
    print("done", stop, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
