"""`samba serve`: run the live capture server until Ctrl-C (or `--duration`)."""

from __future__ import annotations

import argparse
import asyncio
import functools
import os
import sys
from pathlib import Path

from threadpoolctl import threadpool_limits

from samba.base import InputError, address, bind_address, finite_float, natural, positive_float
from samba.reconstruct import METHODS
from samba.service.node_keys import read_node_keys
from samba.service.replay_guard import DEFAULT_MAX_SKEW_S
from samba.service.serve import (
    CORES,
    HTTP_PORT,
    UDP_PORT,
    LiveServer,
    auto_workers,
    serve_until_stopped,
)
from samba.service.session import CaptureSession
from samba.service.session_config import INPUTS, LABELLERS, SessionConfig, read_sessions
from samba.service.session_policy import DEFAULT_MAX_SESSIONS, SessionPolicy


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `serve` arguments to `parser`."""
    parser.description = (
        "Receive camera-node packets, reconstruct each session's skeleton, stream it as VMC "
        "to game engines and to the live viewer, and record takes on request."
    )
    one = parser.add_argument_group("one session from flags (or use --config)")
    one.add_argument(
        "--config",
        metavar="FILE",
        help="TOML file of [[session]] tables, see docs/live.md (default: one session from "
        "the flags below)",
    )
    one.add_argument(
        "--input",
        choices=INPUTS,
        default="markers",
        help="what the nodes send: markers (calibrated cameras, the default) or poses "
        "(one markerless node, samba node --mode silhouette; no --calib or --db)",
    )
    one.add_argument(
        "--calib",
        metavar="FILE",
        help="camera calibration TOML; camera id n = n-th camera (needed for markers; no default)",
    )
    one.add_argument(
        "--db", metavar="STORE", help="pose store directory (needed for markers; no default)"
    )
    one.add_argument(
        "--session", default="default", metavar="NAME", help="session name (default: default)"
    )
    one.add_argument(
        "--method",
        default="samba",
        choices=sorted(METHODS),
        help="reconstruction method, as samba eval --methods names them (default samba)",
    )
    one.add_argument(
        "--fps",
        type=positive_float,
        default=60.0,
        metavar="N",
        help="camera frame rate (default 60)",
    )
    one.add_argument(
        "--vmc",
        type=address,
        action="append",
        default=[],
        metavar="HOST:PORT",
        help="send VMC to this receiver (repeatable), e.g. 127.0.0.1:39539 (default: none)",
    )
    one.add_argument(
        "--avatar",
        metavar="FILE",
        help="avatar file (.vrm, .glb, .gltf, .usd, .usda, .usdc, .usdz) whose rig the VMC "
        "stream uses (default: the built-in mannequin)",
    )
    one.add_argument(
        "--wait-ms",
        type=float,
        default=50.0,
        metavar="MS",
        help="wait for late cameras, milliseconds (default 50)",
    )
    one.add_argument(
        "--labels",
        choices=LABELLERS,
        default="auto",
        help="who labels the markers: the server finds the labels the nodes lost from "
        "every camera's blobs (server), or the nodes' labels as sent (nodes); auto "
        "(default): server with 3 or more cameras",
    )
    one.add_argument(
        "--calibrate-subject",
        type=finite_float,
        default=0.0,
        metavar="SECONDS",
        help="calibrate the subject's skin-marker offsets from the session's first SECONDS "
        "(the subject moves naturally meanwhile) and remove them after; stored with takes "
        "(default 0: none)",
    )
    net = parser.add_argument_group("network")
    net.add_argument(
        "--udp",
        type=bind_address,
        default=("127.0.0.1", UDP_PORT),
        metavar="HOST:PORT",
        help=f"where camera nodes send (default 127.0.0.1:{UDP_PORT}; 0.0.0.0 for other hosts, "
        "which needs --keys)",
    )
    net.add_argument(
        "--http",
        type=bind_address,
        default=("127.0.0.1", HTTP_PORT),
        metavar="HOST:PORT",
        help=f"control API and viewer (default 127.0.0.1:{HTTP_PORT})",
    )
    net.add_argument("--no-http", action="store_true", help="no control API or viewer")
    net.add_argument(
        "--token",
        help="API token, at least 16 characters (default $SAMBA_TOKEN, else drawn at start "
        "and printed in the viewer's URL)",
    )
    net.add_argument(
        "--token-file",
        metavar="FILE",
        help="write the API token to FILE, readable by you only, instead of printing it; "
        "rewritten at every start (default: printed)",
    )
    net.add_argument(
        "--allow-host",
        action="append",
        default=[],
        metavar="NAME",
        help="a DNS name browsers reach the viewer and API by (repeatable); its address, "
        "and localhost on loopback, always work (default: none)",
    )
    net.add_argument(
        "--keys",
        metavar="FILE",
        help="the nodes' keys (TOML, [[node]] tables: key_file, cameras, session); packets "
        "must then be signed, each by the key of its camera; needed beyond loopback "
        "(default: unsigned packets, loopback only)",
    )
    net.add_argument(
        "--max-skew",
        type=positive_float,
        default=DEFAULT_MAX_SKEW_S,
        metavar="SECONDS",
        help="drop packets whose timestamp is further than this from the server's clock "
        f"(default {DEFAULT_MAX_SKEW_S:g}; the nodes' clocks must agree that well)",
    )
    api = parser.add_argument_group("sessions started over the control API")
    api.add_argument(
        "--api-files",
        action="append",
        default=[],
        metavar="DIR",
        help="a folder whose calibrations, stores and avatars API sessions may name "
        "(repeatable); besides it only the files given here at start (default: none)",
    )
    api.add_argument(
        "--api-vmc",
        type=address,
        action="append",
        default=[],
        metavar="HOST:PORT",
        help="a VMC receiver API sessions may send to (repeatable); besides it only those "
        "given here at start (default: none)",
    )
    api.add_argument(
        "--max-sessions",
        type=natural,
        default=DEFAULT_MAX_SESSIONS,
        metavar="N",
        help=f"most sessions the server runs (default {DEFAULT_MAX_SESSIONS})",
    )
    parser.add_argument(
        "--workers",
        type=_workers,
        default="auto",
        help="processes computing the frames, sessions spread over them; 0 = in the "
        "server's event loop; auto (default) = 0 when no session has the server find "
        f"lost labels, else one per core ({CORES} here)",
    )
    parser.add_argument(
        "--out-dir",
        default="takes",
        metavar="DIR",
        help="folder recorded takes go into, as DIR/SESSION/TAKE.mcap (default ./takes)",
    )
    parser.add_argument(
        "--record",
        nargs="?",
        const="",
        metavar="NAME",
        help="record a take in every session from the start, named NAME if given (default: "
        "record only when asked over the API)",
    )
    parser.add_argument(
        "--duration", type=positive_float, help="stop after this many seconds (default: Ctrl-C)"
    )
    parser.set_defaults(run=run, usage_error=parser.error)  # flag conflicts exit 2


def run(args: argparse.Namespace) -> int:
    """Start the server, print where it listens, serve, print a summary at the end."""
    configs = _configs(args)
    keys = read_node_keys(args.keys) if args.keys else None
    if args.max_sessions < 1:
        raise InputError("--max-sessions", "must be at least 1")
    policy = SessionPolicy.of(
        configs, [Path(folder) for folder in args.api_files], args.api_vmc, args.max_sessions
    )
    server = LiveServer(
        configs,
        args.out_dir,
        udp=args.udp,
        http=None if args.no_http else args.http,
        token=args.token or os.environ.get("SAMBA_TOKEN") or None,
        allow_hosts=args.allow_host,
        policy=policy,
        keys=keys,
        max_skew_s=args.max_skew,
        workers=auto_workers(configs) if args.workers == "auto" else args.workers,
    )
    if args.token_file:
        _write_token_file(Path(args.token_file), server.token)
    started = functools.partial(_print_start, token_file=args.token_file)
    # Per-frame linear algebra is on 39 x 39 matrices: BLAS threads only contend with
    # the event loop (and each other) for the cores.
    with threadpool_limits(1):
        metrics, takes = asyncio.run(
            serve_until_stopped(server, args.record, args.duration, started=started)
        )
    _print_summary(metrics, takes)
    return 0


def _workers(text: str) -> int | str:
    """`--workers`: "auto" or a count >= 0."""
    return "auto" if text == "auto" else natural(text)


def _configs(args: argparse.Namespace) -> list[SessionConfig]:
    if args.config:
        if args.calib or args.db:
            args.usage_error("give either --config or --calib/--db, not both")
        return read_sessions(args.config)
    if args.input == "markers" and not (args.calib and args.db):
        args.usage_error("give --config FILE, or --calib FILE and --db STORE")
    values = {
        "name": args.session,
        "input": args.input,
        "method": args.method,
        "fps": args.fps,
        "vmc": [f"{host}:{port}" for host, port in args.vmc],
        "wait_ms": args.wait_ms,
        "labels": args.labels,
        "calibrate_s": args.calibrate_subject,
    }
    for key, value in (("calibration", args.calib), ("database", args.db), ("avatar", args.avatar)):
        if value:
            values[key] = value
    return [SessionConfig.from_mapping(values, "--session")]


def _write_token_file(path: Path, token: str) -> None:
    """Write `token` to `path`, readable and writable by its owner only (mode 0600, also
    when the file existed); `InputError` naming the file when it cannot be written."""
    try:
        descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(descriptor, "w", encoding="ascii") as file:
            os.fchmod(file.fileno(), 0o600)
            file.write(token + "\n")
    except OSError as exc:
        raise InputError(str(path), f"cannot write the token: {exc.strerror or exc}") from None


def _print_start(
    server: LiveServer, sessions: list[CaptureSession], token_file: str | None = None
) -> None:
    host, port = server.udp_address
    print(f"samba serve: camera packets on udp {host}:{port}")
    for s in sessions:
        c = s.config
        vmc = ", ".join(f"{h}:{p}" for h, p in c.vmc) or "none"
        source = (
            "the poses of one markerless node"
            if s.cameras is None
            else f"{len(s.cameras)} cameras ({c.calibration}), database {c.database} "
            f"({s.database_poses} poses), method {c.method}"
        )
        print(f"  session {s.name}: {source}, {c.fps:g} fps, VMC -> {vmc}")
        if server.http_url:
            viewer = f"{server.http_url}/viewer/{s.name}?token=<the token in {token_file}>"
            print(f"    viewer: {viewer if token_file else server.viewer_url(s.name)}")
        take = s.recording
        if take is not None:
            print(f"    recording take {take.name} -> {take.path}")
    if server.workers:
        print(f"  frames computed in {server.workers} worker processes")
    else:
        print("  frames computed in the event loop, those that arrive together in one batch")
    if server.http_url:
        token = f"the token in {token_file}" if token_file else server.token
        print(f"  control API: {server.http_url}/api/health, Authorization: Bearer {token}")
        print("  (Ctrl-C stops)")
    sys.stdout.flush()


def _print_summary(metrics: dict, takes: list) -> None:
    dropped = metrics["dropped"]
    reasons = ", ".join(f"{reason} {n}" for reason, n in dropped.items() if reason != "total")
    print(
        f"samba serve: stopped; {metrics['datagrams']} datagrams in, {dropped['total']} dropped"
        + (f" ({reasons})" if reasons else "")
    )
    for name, m in metrics["sessions"].items():
        sync, latency = m["sync"], m["latency"]
        frames = f"{sync['complete']} complete, {sync['partial']} partial"
        if m["labels"] is not None:  # a marker session: cameras make its frames
            frames += f", {sync['skipped']} skipped: too few cameras"
        timing = (
            f"latency p50 {latency['p50_ms']} ms, p99 {latency['p99_ms']} ms"
            if latency["p50_ms"] is not None
            else "no latency: no frame came"
        )
        print(f"  session {name}: {m['frames_out']} frames out ({frames}); {timing}")
    for take in takes:
        print(f"  take {take.name}: {take.frames} frames -> {Path(take.path)}")
