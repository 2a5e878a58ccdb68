"""The evaluation of EVALUATION.md over many takes, every method in one run (`samba eval`).

`evaluate` captures every test take once (`samba.evaluation.protocol`) and reconstructs it
with every run; a test take's database is every training take but itself. The pose index
comes from the caller (`build_index`, e.g. `samba.db.PoseIndex.build`), so this package
needs nothing of `samba.db`, and the takes come in memory, so it reads no files.
`Evaluation.report` gives the text tables (`samba.evaluation.report`), `Evaluation.document`
the JSON document, `write_plots` the PNG plots (`samba.evaluation.plots`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property, partial
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from samba.base import InputError, outcomes_in_order
from samba.body import mirror_poses
from samba.evaluation import report
from samba.evaluation.protocol import TakeErrors, capture_take, run_method, summarize
from samba.evaluation.report import SweepPoint
from samba.reconstruct import Method, NeighbourSource, method

NamedPoses = tuple[str, np.ndarray]
"""A take in memory: its name and its poses (F, 13, 3) in meters at 30 fps."""
SWEEP_N_AT_K = (10, 20, 30)
"""The K values of the N sweep (the paper's Fig. 9)."""
IndexBuilder = Callable[[np.ndarray], NeighbourSource]
"""Builds the pose index of database poses (n, 13, 3) m, e.g. `samba.db.PoseIndex.build`."""


@dataclass(frozen=True)
class Evaluation:
    """The outcome of `evaluate`: per run label, the errors of every test take in test
    order; `left_out` names the test takes that are also training takes (each left out
    of its own database); `test_frames` the frames evaluated per test take; `train` the
    training takes' names; `seed`, `dropout` and `new_user` the capture it was run with."""

    results: dict[str, list[TakeErrors]]
    left_out: tuple[str, ...]
    test_frames: dict[str, int]
    train: tuple[str, ...]
    seed: int
    dropout: float
    new_user: bool

    @cached_property
    def summaries(self) -> dict[str, dict[str, object]]:
        """`samba.evaluation.protocol.summarize` of every run, by label (computed once)."""
        return {label: summarize(takes) for label, takes in self.results.items()}

    @property
    def mode(self) -> str:
        """Which split was evaluated, in words."""
        tests = len(self.test_frames)
        if not self.left_out:
            return f"held-out test set: none of the {tests} test takes is in the training set"
        if len(self.left_out) == tests:
            return f"leave-one-take-out: each of the {tests} test takes is left out of its database"
        return (
            f"mixed: {len(self.left_out)} of the {tests} test takes are also training takes "
            "and are left out of their own database"
        )


def evaluate(
    train: Sequence[NamedPoses],
    test: Sequence[NamedPoses],
    runs: Mapping[str, Method],
    build_index: IndexBuilder,
    seed: int = 0,
    dropout: float = 0.0,
    new_user: bool = False,
    progress: bool | None = False,
    client: Any = None,
) -> Evaluation:
    """Capture every test take once and reconstruct it with every run (label -> method).

    A test take's database is every training take except one of the same name (leave-one-
    take-out), plus the mirror images of those poses for methods with `mirrored_database`;
    each index variant is built once per test take (`build_index`) and shared by the runs.
    Test take i is
    captured with seed `seed + i` (`samba.evaluation.protocol.capture_take`, with `dropout` and
    `new_user`). `progress` None shows a progress bar on a terminal only. Raises
    `InputError` when a database is empty or smaller than a run's K. With a Dask `client`
    (`samba.base.cluster_client`) each test take is a task on its workers (`evaluate_take`;
    the training takes reach each worker once): the same errors, the times of the workers.
    """
    train_names = {name for name, _ in train}
    results: dict[str, list[TakeErrors]] = {label: [] for label in runs}
    tests = [(number, name, poses) for number, (name, poses) in enumerate(test)]
    task = partial(
        evaluate_take,
        runs=runs,
        build_index=build_index,
        seed=seed,
        dropout=dropout,
        new_user=new_user,
    )
    if client is None:
        outcomes: Iterable[tuple[Any, Any]] = _run_here(task, tests, train, progress)
    else:
        outcomes = outcomes_in_order(
            client, task, tests, (train,), progress, unit="take", name=lambda t: t[1]
        )
    for _, outcome in outcomes:
        if isinstance(outcome, BaseException):
            raise outcome
        for label, errors in outcome.items():
            results[label].append(errors)
    left_out = tuple(name for name, _ in test if name in train_names)
    frames = {name: len(poses) for name, poses in test}
    names = tuple(name for name, _ in train)
    return Evaluation(results, left_out, frames, names, seed, dropout, new_user)


def evaluate_take(
    test: tuple[int, str, np.ndarray],
    train: Sequence[NamedPoses],
    runs: Mapping[str, Method],
    build_index: IndexBuilder,
    seed: int = 0,
    dropout: float = 0.0,
    new_user: bool = False,
) -> dict[str, TakeErrors]:
    """The errors of every run (label -> method) on test take `test` = (number, name,
    poses (F, 13, 3) m), captured with seed `seed + number`, its database every training
    take but one of its name (`evaluate`); single-threaded, as the protocol times it."""
    number, name, poses = test
    database = [p for other, p in train if other != name]
    if not database:
        raise InputError("--train", f"no training take is left for test take {name}")
    indexes = DatabaseIndexes(np.concatenate(database), build_index)
    take = capture_take(name, poses, seed=seed + number, dropout=dropout, new_user=new_user)
    errors = {}
    with threadpool_limits(limits=1):
        for label, m in runs.items():
            index = indexes.get(m.mirrored_database)
            if m.config.k > len(index):
                raise InputError(
                    label, f"K = {m.config.k} exceeds the {len(index)} poses of {name}'s database"
                )
            errors[label] = run_method(m.build(index), take)
    return errors


def _run_here(
    task: Callable[..., dict[str, TakeErrors]],
    tests: Sequence[tuple[int, str, np.ndarray]],
    train: Sequence[NamedPoses],
    progress: bool | None,
) -> Iterator[tuple[tuple[int, str, np.ndarray], dict[str, TakeErrors]]]:
    """(test, `task(test, train)`) for every test take in order, in this process, under a
    progress bar (None: on a terminal only) naming the take."""
    bar = tqdm(tests, unit="take", disable=None if progress is None else not progress)
    for test in bar:
        bar.set_postfix_str(test[1], refresh=False)
        yield test, task(test, train)


class DatabaseIndexes:
    """The pose indexes of a database, plain and mirrored, each built on first use."""

    def __init__(self, poses: np.ndarray, build: IndexBuilder) -> None:
        self.poses = poses
        self._build = build
        self._built: dict[bool, NeighbourSource] = {}

    def get(self, mirrored: bool) -> NeighbourSource:
        """The index of the poses, with their mirror images when `mirrored`."""
        if mirrored not in self._built:
            poses = (
                np.concatenate([self.poses, mirror_poses(self.poses)]) if mirrored else self.poses
            )
            self._built[mirrored] = self._build(poses)
        return self._built[mirrored]


def sweep_points(
    runs: dict[str, Method], sweep_k: Sequence[int], sweep_n: Sequence[int], k_sweep_n: int | None
) -> dict[str, list[SweepPoint]]:
    """The `samba` configurations of the K sweep (N = k_sweep_n, default the paper's) and of the
    N sweep (K = 10, 20, 30), added to `runs` under labels such as "samba K=20 N=5"
    (a point equal to a run already there reuses it). Returns {"k": ..., "n": ...} for
    the sweeps requested, each a list of (K, N, label)."""
    samba = method("samba")
    labels = {(m.config.k, m.config.n): lab for lab, m in runs.items() if m.name == samba.name}

    def point(k: int, n: int) -> SweepPoint:
        label = labels.setdefault((k, n), f"samba K={k} N={n}")
        runs.setdefault(label, samba.with_sizes(k, n))
        return k, n, label

    sweeps = {}
    if sweep_k:
        sweeps["k"] = [point(k, k_sweep_n or samba.config.n) for k in sweep_k]
    if sweep_n:
        sweeps["n"] = [point(k, n) for k in SWEEP_N_AT_K for n in sweep_n]
    return sweeps


def report_text(
    evaluation: Evaluation,
    main: Sequence[str],
    sweeps: Mapping[str, Sequence[SweepPoint]],
) -> str:
    """The text report of `samba eval`: the split, the overall, per-take and per-joint
    tables of the runs labelled `main`, and the sweep tables of `sweeps`."""
    summaries = evaluation.summaries
    chosen = {label: summaries[label] for label in main}
    frames = sum(evaluation.test_frames.values())
    variant = [
        f"dropout {evaluation.dropout:g}" if evaluation.dropout else "",
        "new user" if evaluation.new_user else "",
    ]
    lines = [
        evaluation.mode,
        f"{len(evaluation.train)} training takes, {len(evaluation.test_frames)} test takes, "
        f"{frames} test frames; seed {evaluation.seed}" + "".join(f"; {v}" for v in variant if v),
        "errors in cm at a 45 cm tibia (m: unscaled meters); time per frame of the live path\n",
        report.overall_table(chosen),
    ]
    gains = report.improvements(chosen)
    if gains:
        lines.append(f"\n{gains}")
    lines.append(f"\nper take (MPJPE cm)\n{report.per_take_table(chosen, evaluation.test_frames)}")
    lines.append(f"\nper joint (cm)\n{report.per_joint_table(chosen)}")
    if "k" in sweeps:
        lines.append(f"\nK sweep, samba (Fig. 8)\n{report.k_sweep_table(sweeps['k'], summaries)}")
    if "n" in sweeps:
        lines.append(f"\nN sweep, samba (Fig. 9)\n{report.n_sweep_table(sweeps['n'], summaries)}")
    return "\n".join(lines)


def document(
    evaluation: Evaluation,
    runs: Mapping[str, Method],
    main: Sequence[str],
    sweeps: Mapping[str, Sequence[SweepPoint]],
    max_frames: int | None,
) -> dict[str, object]:
    """The JSON document of `samba eval`: the settings (what was evaluated and how, with
    `max_frames` frames per test take at most), the summaries of the runs labelled `main`
    and the sweep points."""
    summaries = evaluation.summaries
    settings = {
        "train": list(evaluation.train),
        "test": evaluation.test_frames,
        "mode": evaluation.mode,
        "left_out": list(evaluation.left_out),
        "seed": evaluation.seed,
        "dropout": evaluation.dropout,
        "new_user": evaluation.new_user,
        "max_frames": max_frames,
        "single_threaded": True,
        "methods": {
            label: {
                "description": m.description,
                "nearest_only": m.nearest_only,
                "mirrored_database": m.mirrored_database,
                **dataclasses.asdict(m.config),
            }
            for label, m in runs.items()
        },
    }
    return {
        "settings": settings,
        "methods": {label: summaries[label] for label in main},
        "sweeps": {
            axis: [{"k": k, "n": n, **summaries[label]} for k, n, label in points]
            for axis, points in sweeps.items()
        },
    }


def write_plots(
    directory: Path,
    evaluation: Evaluation,
    main: Sequence[str],
    sweeps: Mapping[str, Sequence[SweepPoint]],
) -> list[Path]:
    """Draw the PNG plots of the runs labelled `main` (error over time per take, error
    per joint) and of the sweeps (the paper's Fig. 8 and 9) into `directory`; returns
    the files written. matplotlib is loaded only here."""
    from samba.evaluation import plots

    summaries = evaluation.summaries
    chosen = {label: summaries[label] for label in main}
    written = plots.error_over_time({label: evaluation.results[label] for label in main}, directory)
    written.append(plots.error_per_joint(chosen, directory / "error_per_joint.png"))
    if "k" in sweeps:
        written.append(plots.k_sweep(sweeps["k"], summaries, directory / "fig8_k_sweep.png"))
    if "n" in sweeps:
        written.append(plots.n_sweep(sweeps["n"], summaries, directory / "fig9_n_sweep.png"))
    return written
