"""`samba eval`: the accuracy protocol of EVALUATION.md over BVH files, every method in one run.

This module is the composition root of the evaluation: it reads BVH files (`ingest`) and
builds pose indexes (`db`); the capture math it drives (`samba.evaluation.protocol`,
`samba.reconstruct.methods`, `samba.reconstruct.reconstruction`) never imports either.
`evaluate` is the core loop over in-memory takes; the command line wraps it with file
loading, text tables (`samba.evaluation.report`), a JSON document and PNG plots
(`samba.evaluation.plots`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from samba.base.arguments import positive
from samba.base.atomic_file import write_text_atomic
from samba.base.errors import InputError
from samba.body.skeleton import mirror_poses
from samba.db.index import PoseIndex
from samba.evaluation import report as eval_report
from samba.evaluation.protocol import TakeErrors, capture_take, run_method, summarize
from samba.evaluation.report import SweepPoint
from samba.ingest.batch import expand_paths
from samba.ingest.bvh_take import load_bvh_take
from samba.reconstruct.methods import METHODS, Method, method

NamedPoses = tuple[str, np.ndarray]
"""A take in memory: its name and its poses (F, 13, 3) in meters at 30 fps."""
SWEEP_N_AT_K = (10, 20, 30)
"""The K values of the N sweep (the paper's Fig. 9)."""
"""Environment variables that limit the BLAS threads (read when numpy loads)."""


@dataclass(frozen=True)
class Evaluation:
    """The outcome of `evaluate`: per run label, the errors of every test take in test
    order; `left_out` names the test takes that are also training takes (each left out
    of its own database); `test_frames` the frames evaluated per test take."""

    results: dict[str, list[TakeErrors]]
    left_out: tuple[str, ...]
    test_frames: dict[str, int]

    def summaries(self) -> dict[str, dict[str, object]]:
        """`samba.evaluation.protocol.summarize` of every run, by label."""
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
    seed: int = 0,
    dropout: float = 0.0,
    new_user: bool = False,
    progress: bool | None = False,
) -> Evaluation:
    """Capture every test take once and reconstruct it with every run (label -> method).

    A test take's database is every training take except one of the same name (leave-one-
    take-out), plus the mirror images of those poses for methods with `mirrored_database`;
    each index variant is built once per test take and shared by the runs. Test take i is
    captured with seed `seed + i` (`samba.evaluation.protocol.capture_take`, with `dropout` and
    `new_user`). `progress` None shows a progress bar on a terminal only. Raises
    `InputError` when a database is empty or smaller than a run's K.
    """
    train_names = {name for name, _ in train}
    results: dict[str, list[TakeErrors]] = {label: [] for label in runs}
    bar = tqdm(test, unit="take", disable=None if progress is None else not progress)
    for number, (name, poses) in enumerate(bar):
        bar.set_postfix_str(name, refresh=False)
        database = [p for other, p in train if other != name]
        if not database:
            raise InputError("--train", f"no training take is left for test take {name}")
        indexes = _Indexes(np.concatenate(database))
        take = capture_take(name, poses, seed=seed + number, dropout=dropout, new_user=new_user)
        for label, m in runs.items():
            index = indexes.get(m.mirrored_database)
            if m.config.k > len(index):
                raise InputError(
                    label, f"K = {m.config.k} exceeds the {len(index)} poses of {name}'s database"
                )
            results[label].append(run_method(m.build(index), take))
    left_out = tuple(name for name, _ in test if name in train_names)
    return Evaluation(results, left_out, {name: len(poses) for name, poses in test})


class _Indexes:
    """The pose indexes of one test take's database, plain and mirrored, built on demand."""

    def __init__(self, poses: np.ndarray) -> None:
        self.poses = poses
        self._built: dict[bool, PoseIndex] = {}

    def get(self, mirrored: bool) -> PoseIndex:
        """The index of the poses, with their mirror images when `mirrored`."""
        if mirrored not in self._built:
            poses = (
                np.concatenate([self.poses, mirror_poses(self.poses)]) if mirrored else self.poses
            )
            self._built[mirrored] = PoseIndex.build(poses)
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


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `eval` arguments to `parser`."""
    parser.add_argument(
        "--train", nargs="+", required=True, metavar="PATH", help="BVH files and/or folders"
    )
    parser.add_argument(
        "--test",
        nargs="+",
        required=True,
        metavar="PATH",
        help="BVH files and/or folders; a test take also given in --train is left out of "
        "its own database (so --train D --test D is leave-one-take-out over D)",
    )
    parser.add_argument(
        "--methods",
        type=_method_list,
        default=list(METHODS),
        metavar="NAME,...",
        help=f"methods to compare (default {','.join(METHODS)})",
    )
    parser.add_argument("--K", type=positive, help="neighbours K for every method but nn")
    parser.add_argument("--N", type=positive, help="pseudo-poses N for every method but nn")
    parser.add_argument(
        "--dropout",
        type=_fraction,
        default=0.0,
        help="fraction of marker observations missing at random from frame 2 on (e.g. 0.1)",
    )
    parser.add_argument(
        "--new-user",
        action="store_true",
        help="scale the test bodies' limbs by random factors in [0.9, 1.1]",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="capture seed; test take i uses seed + i"
    )
    parser.add_argument("--json", metavar="OUT", help="write settings and summaries as JSON")
    parser.add_argument("--plots", metavar="DIR", help="write PNG plots into this folder")
    parser.add_argument(
        "--sweep-k",
        type=_int_list,
        default=[],
        metavar="K,...",
        help="also run samba with these K (the paper's Fig. 8), e.g. 1,2,5,10,20,30,50",
    )
    parser.add_argument(
        "--sweep-n",
        type=_int_list,
        default=[],
        metavar="N,...",
        help="also run samba with these N for K = 10, 20, 30 (Fig. 9), e.g. 1,2,5,10,20",
    )
    parser.add_argument(
        "--max-frames",
        type=positive,
        metavar="F",
        help="evaluate only the first F frames of each test take",
    )
    parser.set_defaults(run=_run)


def _int_list(text: str) -> list[int]:
    return [positive(part) for part in text.split(",") if part.strip()]


def _method_list(text: str) -> list[str]:
    names = [part.strip() for part in text.split(",") if part.strip()]
    for name in names:
        if name not in METHODS:
            raise argparse.ArgumentTypeError(
                f"unknown method {name!r}; known: {', '.join(METHODS)}"
            )
    if not names:
        raise argparse.ArgumentTypeError("no method given")
    return list(dict.fromkeys(names))


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {value}")
    return value


def _files(paths: Sequence[str], flag: str) -> list[Path]:
    """The BVH files under paths (folders searched), resolved, each once."""
    files = list(dict.fromkeys(p.resolve() for p in expand_paths(paths)))
    if not files:
        raise InputError(f"{flag} {' '.join(paths)}", "no .bvh files found")
    return files


def _load(files: Sequence[Path]) -> dict[Path, NamedPoses]:
    """The take of every file, named by its file stem (by its path where stems collide)."""
    stems = [f.stem for f in files]
    return {
        f: (f.stem if stems.count(f.stem) == 1 else str(f), load_bvh_take(f).poses) for f in files
    }


def _run(args: argparse.Namespace) -> int:
    if args.plots:
        if Path(args.plots).exists() and not Path(args.plots).is_dir():
            raise InputError("--plots", f"{args.plots} is a file; plots go into a folder")
        Path(args.plots).mkdir(parents=True, exist_ok=True)
    if args.json and not Path(args.json).resolve().parent.is_dir():
        raise InputError("--json", f"folder of {args.json} does not exist")
    train = _files(args.train, "--train")
    test = _files(args.test, "--test")
    takes = _load(list(dict.fromkeys(train + test)))
    train_takes = [takes[f] for f in train]
    test_takes = [(name, poses[: args.max_frames]) for name, poses in (takes[f] for f in test)]
    runs = {name: method(name).with_sizes(args.K, args.N) for name in args.methods}
    sweeps = sweep_points(runs, args.sweep_k, args.sweep_n, args.N)
    with threadpool_limits(limits=1):  # the protocol times single-threaded reconstruction
        evaluation = evaluate(
            train_takes, test_takes, runs, args.seed, args.dropout, args.new_user, progress=None
        )
    summaries = evaluation.summaries()
    main = {name: summaries[name] for name in args.methods}
    _print_report(args, evaluation, main, sweeps, summaries, len(train_takes))
    if args.json:
        document = {
            "settings": _settings(args, runs, evaluation, train_takes),
            "methods": main,
            "sweeps": {
                axis: [{"k": k, "n": n, **summaries[label]} for k, n, label in points]
                for axis, points in sweeps.items()
            },
        }
        write_text_atomic(args.json, json.dumps(document, indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.plots:
        _plot(Path(args.plots), evaluation, main, sweeps, summaries)
    return 0


def _print_report(
    args: argparse.Namespace,
    evaluation: Evaluation,
    main: Mapping[str, Mapping[str, object]],
    sweeps: Mapping[str, Sequence[SweepPoint]],
    summaries: Mapping[str, Mapping[str, object]],
    train_count: int,
) -> None:
    frames = sum(evaluation.test_frames.values())
    variant = [
        f"dropout {args.dropout:g}" if args.dropout else "",
        "new user" if args.new_user else "",
    ]
    print(evaluation.mode)
    print(
        f"{train_count} training takes, {len(evaluation.test_frames)} test takes, "
        f"{frames} test frames; seed {args.seed}" + "".join(f"; {v}" for v in variant if v)
    )
    print("errors in cm at a 45 cm tibia (m: unscaled meters); time per frame of the live path\n")
    print(eval_report.overall_table(main))
    gains = eval_report.improvements(main)
    if gains:
        print(f"\n{gains}")
    print(f"\nper take (MPJPE cm)\n{eval_report.per_take_table(main, evaluation.test_frames)}")
    print(f"\nper joint (cm)\n{eval_report.per_joint_table(main)}")
    if "k" in sweeps:
        print(f"\nK sweep, samba (Fig. 8)\n{eval_report.k_sweep_table(sweeps['k'], summaries)}")
    if "n" in sweeps:
        print(f"\nN sweep, samba (Fig. 9)\n{eval_report.n_sweep_table(sweeps['n'], summaries)}")


def _settings(
    args: argparse.Namespace,
    runs: Mapping[str, Method],
    evaluation: Evaluation,
    train: Sequence[NamedPoses],
) -> dict[str, object]:
    """What was evaluated and how, for the JSON document."""
    return {
        "train": [name for name, _ in train],
        "test": evaluation.test_frames,
        "mode": evaluation.mode,
        "left_out": list(evaluation.left_out),
        "seed": args.seed,
        "dropout": args.dropout,
        "new_user": args.new_user,
        "max_frames": args.max_frames,
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


def _plot(
    directory: Path,
    evaluation: Evaluation,
    main: Mapping[str, Mapping[str, object]],
    sweeps: Mapping[str, Sequence[SweepPoint]],
    summaries: Mapping[str, Mapping[str, object]],
) -> None:
    from samba.evaluation import (
        plots as eval_plots,  # matplotlib loads only when plots are asked for
    )

    written = eval_plots.error_over_time(
        {name: evaluation.results[name] for name in main}, directory
    )
    written.append(eval_plots.error_per_joint(main, directory / "error_per_joint.png"))
    if "k" in sweeps:
        written.append(eval_plots.k_sweep(sweeps["k"], summaries, directory / "fig8_k_sweep.png"))
    if "n" in sweeps:
        written.append(eval_plots.n_sweep(sweeps["n"], summaries, directory / "fig9_n_sweep.png"))
    print(f"wrote {len(written)} plots to {directory}")
