"""The `samba` console command: one entry point, a subcommand per area.

`AREAS` says what each `samba X` runs: the function that adds its arguments, which lives
in the `cli` module of the package that owns the area (`samba.db.cli`, `samba.ingest.cli`,
`samba.export.cli`, `samba.service.cli.*`, `samba.cameras.cli` for `calibrate`); `eval`
is parsed here. Every `cli` module only parses arguments and calls its package's API.
This module is the top layer: it may import every package, and none imports it.

A `SambaError` (or an operating system error such as a full disk) is printed as one
line on stderr with exit status 1; wrong flags exit with status 2 (argparse).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from threadpoolctl import threadpool_limits

from samba.base import (
    InputError,
    SambaError,
    add_cluster_arguments,
    add_force_argument,
    check_outputs,
    cluster_client,
    kernels_enabled,
    positive,
    seconds_range,
    write_text_atomic,
)
from samba.cameras import cli as calibrate_cli
from samba.db import PoseIndex, index_kernels
from samba.db import cli as store_cli
from samba.evaluation import (
    EVALUATION_FPS,
    MarkerTest,
    document,
    evaluate,
    evaluate_markers,
    marker_document,
    marker_report,
    report_text,
    sweep_points,
    write_plots,
)
from samba.export import avatar_humanoid
from samba.export import cli as export_cli
from samba.ingest import (
    BvhImportOptions,
    MarkerSet,
    RigMap,
    detect_rig,
    expand_paths,
    load_bvh_take,
    read_bvh,
    read_c3d,
    reader_kernels,
    reference_joints,
    resolve_humanoid,
    rig_of,
)
from samba.ingest import cli as import_cli
from samba.reconstruct import METHODS, method, reconstruction_kernels
from samba.service.cli import (
    capture_volume,
    demo,
    examples,
    node,
    reconstruct,
    serve,
    track_video,
)


def _register_db(parser: argparse.ArgumentParser) -> None:
    """`samba db ACTION`: the store's actions (`samba.db.cli`) with `import`
    (`samba.ingest.cli`) second, after `init`."""
    actions = parser.add_subparsers(dest="db_command", required=True, metavar="ACTION")
    store_cli.add_create_action(actions)
    import_cli.add_import_action(actions)
    store_cli.add_store_actions(actions)
    rig = actions.add_parser(
        "rig",
        help="show which joint of a BVH file's or an avatar's skeleton is each humanoid bone",
        description="Map a skeleton's joints to the humanoid bones (samba.ingest.resolver: "
        "names and tree together) and print the mapping with the evidence per bone; "
        "--write-map saves the 13 joints as the mapping file samba db import --map reads.",
    )
    rig.add_argument("file", help="a BVH file, or an avatar (.glb, .gltf, .vrm, .usd*)")
    rig.add_argument(
        "--write-map",
        metavar="FILE.toml",
        help="write the 13-joint mapping file (default: print the mapping only)",
    )
    add_force_argument(rig)
    rig.set_defaults(run=_rig)


def _rig(args: argparse.Namespace) -> int:
    path = Path(args.file)
    if args.write_map:
        check_outputs([args.write_map], args.force, [path])
    if path.suffix.lower() == ".bvh":
        bvh = read_bvh(path)
        tree = bvh.skeleton()
        humanoid = resolve_humanoid(tree, str(path))  # what it cannot place, said plainly
        rig, _ = detect_rig(bvh.names, str(path), lambda: tree)
        found = f"rig {rig.name}"
    else:
        humanoid = avatar_humanoid(path)
        found = "an avatar"
    print(f"{path}: {found}, {len(humanoid.tree.names)} joints")
    print(humanoid.report())
    if args.write_map:
        mapping = rig_of(humanoid.tree, humanoid.capture_joints, path.stem)
        write_text_atomic(args.write_map, mapping.toml())
        print(f"wrote {args.write_map}")
    return 0


def _register_eval(parser: argparse.ArgumentParser) -> None:
    """`samba eval`: the accuracy protocol over BVH files and real marker takes (C3D)
    (`samba.evaluation`)."""
    parser.add_argument(
        "--train", nargs="+", required=True, metavar="PATH", help="BVH files and/or folders"
    )
    parser.add_argument(
        "--test",
        nargs="+",
        required=True,
        metavar="PATH",
        help="BVH and/or C3D files and folders; a BVH test take also given in --train is "
        "left out of its own database (so --train D --test D is leave-one-take-out over "
        "D); a C3D take is scored against reference joint centres from its full marker set",
    )
    parser.add_argument(
        "--methods",
        type=_method_list,
        default=list(METHODS),
        metavar="NAME,...",
        help=f"methods to compare (default {','.join(METHODS)})",
    )
    parser.add_argument(
        "--K",
        type=positive,
        metavar="K",
        help="neighbours K for every method but nn (default: each method's own)",
    )
    parser.add_argument(
        "--N",
        type=positive,
        metavar="N",
        help="pseudo-poses N for every method but nn (default: each method's own)",
    )
    parser.add_argument(
        "--dropout",
        type=_fraction,
        default=0.0,
        metavar="F",
        help="fraction of marker observations missing at random from frame 2 on, e.g. 0.1 "
        "(default 0)",
    )
    parser.add_argument(
        "--new-user",
        action="store_true",
        help="scale the test bodies' limbs by random factors in [0.9, 1.1] (default: as recorded)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="capture seed; test take i uses seed + i (default 0)",
    )
    parser.add_argument(
        "--json", metavar="FILE", help="write settings and summaries as JSON (default: none)"
    )
    parser.add_argument(
        "--plots", metavar="DIR", help="write PNG plots into this folder (default: none)"
    )
    add_force_argument(parser)
    parser.add_argument(
        "--sweep-k",
        type=_int_list,
        default=[],
        metavar="K,...",
        help="also run samba with these K (the paper's Fig. 8), e.g. 1,2,5,10,20,30,50 "
        "(default: none)",
    )
    parser.add_argument(
        "--sweep-n",
        type=_int_list,
        default=[],
        metavar="N,...",
        help="also run samba with these N for K = 10, 20, 30 (Fig. 9), e.g. 1,2,5,10,20 "
        "(default: none)",
    )
    parser.add_argument(
        "--max-frames",
        type=positive,
        metavar="F",
        help="evaluate only the first F frames of each test take (default: all)",
    )
    parser.add_argument(
        "--map",
        metavar="FILE.toml",
        help="joint mapping file for BVH files of a rig not recognised (samba db rig "
        "--write-map writes one; default: detected)",
    )
    real = parser.add_argument_group("real marker takes (C3D)")
    real.add_argument(
        "--markers-3d",
        action="store_true",
        help="reconstruct the recorded 3D markers as they are (default: through the "
        "evaluation cameras, projected, noised and triangulated)",
    )
    real.add_argument(
        "--calibration",
        type=seconds_range,
        default=(0.0, 2.0),
        metavar="A:B",
        help="seconds of each take the subject's skin offsets are calibrated on (default 0:2)",
    )
    import_cli.add_marker_set_argument(real)
    add_cluster_arguments(parser)
    parser.set_defaults(run=_eval)


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


def _bvh_files(paths: Sequence[str], flag: str, spelling: dict[Path, Path]) -> list[Path]:
    """The BVH files under paths (folders searched), each once, spelt as typed: a file
    reached twice (through a link, or spelt two ways) keeps the spelling `spelling`
    (resolved path -> path as typed) first saw."""
    files = list(dict.fromkeys(spelling.setdefault(p.resolve(), p) for p in expand_paths(paths)))
    if not files:
        raise InputError(f"{flag} {' '.join(paths)}", "no .bvh files found")
    return files


def _test_files(paths: Sequence[str], spelling: dict[Path, Path]) -> tuple[list[Path], list[Path]]:
    """The BVH and the C3D files under the --test paths (folders searched), each once,
    spelt as `_bvh_files` spells them."""
    named = [Path(p) for p in paths]
    c3d = [p for p in named if p.suffix.lower() == ".c3d"]
    c3d += [
        f for p in named if p.is_dir() for f in sorted(p.rglob("*")) if f.suffix.lower() == ".c3d"
    ]
    rest = [str(p) for p in named if p.suffix.lower() != ".c3d"]
    found = [spelling.setdefault(p.resolve(), p) for p in expand_paths(rest)] if rest else []
    if not found and not c3d:
        raise InputError(f"--test {' '.join(paths)}", "no .bvh or .c3d files found")
    c3d = [spelling.setdefault(p.resolve(), p) for p in c3d]
    return list(dict.fromkeys(found)), list(dict.fromkeys(c3d))


def _marker_tests(
    files: Sequence[Path], marker_set: str | None, max_frames: int | None
) -> list[MarkerTest]:
    """Real marker takes at 30 fps with their reference joint centres."""
    chosen = MarkerSet.named(marker_set)
    tests = []
    for path in files:
        take = read_c3d(path, chosen).resampled(EVALUATION_FPS)
        truth = reference_joints(take)
        tests.append(MarkerTest(take.name, truth[:max_frames], take.markers[:max_frames]))
    return tests


def _eval(args: argparse.Namespace) -> int:
    if args.plots:
        plots = Path(args.plots)
        if plots.exists() and not plots.is_dir():
            raise InputError("--plots", f"{args.plots} is a file; plots go into a folder")
        check_outputs(sorted(plots.glob("*.png")), args.force)  # plots written before
        plots.mkdir(parents=True, exist_ok=True)
    if args.json:
        check_outputs([args.json], args.force, [*args.train, *args.test])
    spelling: dict[Path, Path] = {}
    train = _bvh_files(args.train, "--train", spelling)
    test, c3d = _test_files(args.test, spelling)
    real = _marker_tests(c3d, args.marker_set, args.max_frames)
    files = list(dict.fromkeys(train + test))
    stems = [f.stem for f in files]  # a take is named by its file stem, or its path if not unique
    options = BvhImportOptions(rig=RigMap.from_toml(args.map) if args.map else None)
    takes = {
        f: (f.stem if stems.count(f.stem) == 1 else str(f), load_bvh_take(f, options).poses)
        for f in files
    }
    train_takes = [takes[f] for f in train]
    test_takes = [(name, poses[: args.max_frames]) for name, poses in (takes[f] for f in test)]
    runs = {name: method(name).with_sizes(args.K, args.N) for name in args.methods}
    sweeps = sweep_points(runs, args.sweep_k, args.sweep_n, args.N) if test_takes else {}
    doc: dict[str, object] = {}
    with threadpool_limits(limits=1):  # the protocol times single-threaded reconstruction
        if test_takes:
            with cluster_client(args.workers, args.cluster) as client:
                evaluation = evaluate(
                    train_takes,
                    test_takes,
                    runs,
                    PoseIndex.build,
                    args.seed,
                    args.dropout,
                    args.new_user,
                    progress=None,
                    client=client,
                )
            print(report_text(evaluation, args.methods, sweeps))
            doc = document(evaluation, runs, args.methods, sweeps, args.max_frames)
        if real:
            start, stop = (round(t * EVALUATION_FPS) for t in args.calibration)
            marked = evaluate_markers(
                train_takes,
                real,
                {name: runs[name] for name in args.methods},
                PoseIndex.build,
                args.seed,
                (start, stop),
                args.markers_3d,
                progress=None,
            )
            print(("\n" if test_takes else "") + marker_report(marked))
            doc["real_markers"] = marker_document(marked)
    if args.json:
        write_text_atomic(args.json, json.dumps(doc, indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.plots and test_takes:
        written = write_plots(Path(args.plots), evaluation, args.methods, sweeps)
        print(f"wrote {len(written)} plots to {args.plots}")
    return 0


def _register_warmup(parser: argparse.ArgumentParser) -> None:
    """`samba warmup`: compile (the first run after an install) or load every compiled
    kernel now, ahead of a live session."""
    parser.set_defaults(run=_warmup)


def _warmup(args: argparse.Namespace) -> int:
    if not kernels_enabled():
        print("compiled kernels are off (SAMBA_KERNELS=numpy, or numba is not installed)")
        return 0
    for kernels in (reconstruction_kernels(), index_kernels(), reader_kernels()):
        cached = kernels.is_cached()
        seconds = kernels.warm_up(sys.stdout)
        print(f"{kernels.name} kernels {'loaded' if cached else 'compiled'} in {seconds:.1f} s")
    return 0


AREAS: dict[str, tuple[Callable[[argparse.ArgumentParser], None], str]] = {
    "db": (
        _register_db,
        "pose database: init, import, ls, show, label, rm, verify, stats, tree, query, rig",
    ),
    "eval": (
        _register_eval,
        "accuracy and speed of every reconstruction method on BVH and real marker (C3D) takes",
    ),
    "calibrate": (
        calibrate_cli.register,
        "calibrate cameras (or one lens) from images or videos of a board; convert calibrations",
    ),
    "reconstruct": (
        reconstruct.register,
        "reconstruct a marker take (C3D, or recorded by samba serve) into a 13-joint take",
    ),
    "export": (
        export_cli.register,
        "retarget takes to a humanoid avatar and write USD, glTF or BVH",
    ),
    "serve": (serve.register, "live capture server: packets in; VMC, viewer, takes out"),
    "demo": (demo.register, "a live capture end to end: server, two camera nodes, take, export"),
    "examples": (
        examples.register,
        "write the input files the README's and docs' examples run on into a folder",
    ),
    "node": (
        node.register,
        "camera node: track the 8 markers (or, markerless, the body) in frames, send them by UDP",
    ),
    "track-video": (
        track_video.register,
        "markerless capture from one camera: silhouettes tracked over the shape tree, as a take",
    ),
    "capture-volume": (
        capture_volume.register,
        "model-free capture from several cameras: visual hull, derived skeleton, BVH",
    ),
    "warmup": (
        _register_warmup,
        "compile (first run after an install) or load the compiled kernels ahead of a session",
    ),
}
"""Subcommand -> (the function that adds its arguments, one-line help)."""


class _CommandParser(argparse.ArgumentParser):
    """A subcommand's parser: arguments it does not know are its error, printed with its
    own usage (`samba db import: error: unrecognized arguments: ...`), not the top-level
    parser's."""

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """Parse `args`; exit 2 with this parser's usage on any it does not know."""
        parsed, extras = super().parse_known_args(args, namespace)
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed, extras


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every area's subcommands."""
    parser = argparse.ArgumentParser(
        prog="samba",
        description="Samba: low-cost real-time motion capture from eight markers.",
    )
    sub = parser.add_subparsers(
        dest="area", required=True, metavar="COMMAND", parser_class=_CommandParser
    )
    for name, (register, help_text) in AREAS.items():
        register(sub.add_parser(name, help=help_text, description=help_text))
    _describe(parser)
    return parser


def _describe(parser: argparse.ArgumentParser) -> None:
    """Give every subcommand of `parser`'s tree without a description of its own its
    one-line help as one, so `samba X Y --help` always says what Y does."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {choice.dest: choice.help for choice in action._choices_actions}
            for name, sub in action.choices.items():
                if not sub.description and helps.get(name):
                    sub.description = f"{helps[name][0].upper()}{helps[name][1:]}."
                _describe(sub)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        status = int(args.run(args) or 0)
        sys.stdout.flush()  # a reader that left (`| head`) shows here, not at exit
        return status
    except BrokenPipeError:  # before OSError, its base class: output piped into `head`
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # for the exit flush
        return 0
    except SambaError as exc:
        print(f"samba: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # disk full, permissions, ... on a path the user gave
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"samba: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("samba: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
