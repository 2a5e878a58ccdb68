"""VMC performer: bundles that python-osc and the npm `osc` package decode into every bone
with the right Unity (left-handed, X-mirrored) values, small enough for Wi-Fi, and a sender
that survives unreachable targets."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from export_fixtures import synthetic_motion
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_server import ThreadingOSCUDPServer
from scipy.spatial.transform import Rotation

from samba.body.skeleton import Body
from samba.export.humanoid import BONE_INDEX, BONE_NAMES, N_BONES, PARENTS, HumanoidRig
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import retarget
from samba.service.errors import ServiceError
from samba.service.vmc import MAX_BUNDLE_BYTES, VmcSender, frame_bundles, unity_pose, vmc_frame

OSC_JS = "osc@2.4.5"
RUNNER = Path(__file__).with_name("osc_receive.js")
FRAME_ADDRESSES = (
    ["/VMC/Ext/Root/Pos"] + ["/VMC/Ext/Bone/Pos"] * N_BONES + ["/VMC/Ext/OK", "/VMC/Ext/T"]
)
ATOL = 1e-6  # floats travel as float32
Receive = Callable[[list[bytes], int], list[dict[str, Any]]]


@pytest.fixture(scope="module")
def arm_raised() -> HumanoidMotion:
    """The default rig retargeted to a rest A-pose and then to the left arm raised straight
    up and out at 45° (our frame: direction (1, 1, 0)), with the pelvis off the origin."""
    body = Body.from_height()
    rest = body.standard_pose()
    raised = rest.copy()
    up_out = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    raised[3] = raised[1] + body.upper_arm * up_out
    raised[5] = raised[3] + body.forearm * up_out
    poses = np.stack([rest, raised]) + np.array([0.3, 0.0, -0.2])
    return retarget(poses, HumanoidRig.from_body(), fps=30.0)


def bone_values(messages: list[tuple[str, list[Any]]]) -> dict[str, np.ndarray]:
    """Bone name -> the 7 floats (px, py, pz, qx, qy, qz, qw) of the `/VMC/Ext/Bone/Pos`
    messages among (address, args) pairs; asserts each bone arrived once."""
    bones = [args for address, args in messages if address == "/VMC/Ext/Bone/Pos"]
    names = [args[0] for args in bones]
    assert sorted(names) == sorted(BONE_NAMES)
    return {args[0]: np.array(args[1:], dtype=np.float64) for args in bones}


def unity_world(values: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """World positions (17, 3) and rotation matrices (17, 3, 3) of received local Unity
    poses, composed as Unity's Transform does (p = p_parent + R_parent p_local, R = R_parent
    R_local, quaternions applied by the usual formula)."""
    positions = np.zeros((N_BONES, 3))
    rotations = np.zeros((N_BONES, 3, 3))
    for j, p in enumerate(PARENTS):
        local = values[BONE_NAMES[j]]
        rotation = Rotation.from_quat(local[3:]).as_matrix()
        if p < 0:
            positions[j], rotations[j] = local[:3], rotation
        else:
            positions[j] = positions[p] + rotations[p] @ local[:3]
            rotations[j] = rotations[p] @ rotation
    return positions, rotations


def assert_frame(values: dict[str, np.ndarray], motion: HumanoidMotion, frame: int) -> None:
    """Received bone values are frame `frame` of `motion`, X-mirrored into Unity's frame."""
    mirror = np.array([-1.0, 1.0, 1.0])
    offsets = motion.rig.offsets
    for name, got in values.items():
        j = BONE_INDEX[name]
        position = motion.root[frame] if j == 0 else offsets[j]
        qx, qy, qz, qw = motion.rotations[frame, j]
        expected = np.concatenate([position * mirror, [qx, -qy, -qz, qw]])
        np.testing.assert_allclose(got, expected, rtol=0, atol=ATOL, err_msg=name)
    positions, _ = unity_world(values)
    expected = motion.world_positions()[frame] * mirror
    np.testing.assert_allclose(positions, expected, rtol=0, atol=1e-5)


class Loopback:
    """A python-osc server on 127.0.0.1 collecting (address, args) of the VMC messages it
    receives; `wait` blocks (bounded) until `expected` messages arrived."""

    def __init__(self, expected: int) -> None:
        self.messages: list[tuple[str, list[Any]]] = []
        self._expected = expected
        self._lock = threading.Lock()
        self._done = threading.Event()
        dispatcher = Dispatcher(strict_timing=False)
        for address in sorted(set(FRAME_ADDRESSES)):
            dispatcher.map(address, self._handle)
        self.server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
        self.server.max_packet_size = 65535
        self.port: int = self.server.server_address[1]
        self._thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self._thread.start()

    def _handle(self, address: str, *args: Any) -> None:
        with self._lock:
            self.messages.append((address, list(args)))
            if len(self.messages) >= self._expected:
                self._done.set()

    def wait(self, timeout: float = 2.0) -> list[tuple[str, list[Any]]]:
        """The messages received so far, once `expected` arrived (fails after `timeout` s)."""
        assert self._done.wait(timeout), f"received {len(self.messages)} of {self._expected}"
        with self._lock:
            return list(self.messages)

    def close(self) -> None:
        """Stops the server and closes its socket."""
        self.server.shutdown()
        self.server.server_close()
        self._thread.join(timeout=2.0)


@pytest.fixture
def loopback() -> Iterator[Loopback]:
    """A `Loopback` expecting one VMC frame's messages."""
    server = Loopback(len(FRAME_ADDRESSES))
    yield server
    server.close()


@pytest.fixture(scope="session")
def osc_receive() -> Receive:
    """Sends datagrams to a fresh node process running `osc_receive.js` and returns the
    messages the npm `osc` package decoded (JSON lines); installs the package once into a
    cache folder under the system temp dir. Skips without node or npm, fails with npm's
    output when the install fails."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("the OSC receiver needs node and npm on PATH")
    tools = Path(tempfile.gettempdir()) / "samba-test-tools" / OSC_JS.replace("@", "-")
    if not (tools / "node_modules" / "osc" / "package.json").is_file():
        install = ["install", "--no-save", "--no-audit", "--no-fund", "--omit=optional"]
        done = subprocess.run(
            [npm, *install, "--prefix", tools, OSC_JS], capture_output=True, text=True
        )
        if done.returncode != 0:
            pytest.fail(f"npm install {OSC_JS} failed:\n{done.stdout}\n{done.stderr}")
    env = {**os.environ, "NODE_PATH": str(tools / "node_modules")}

    def receive(datagrams: list[bytes], count: int) -> list[dict[str, Any]]:
        with subprocess.Popen(
            [node, RUNNER, "0", str(count), "5000"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        ) as process:
            ready = process.stdout.readline()  # bounded: the receiver exits after 5 s
            if not ready:
                pytest.fail(f"the OSC receiver did not start:\n{process.stderr.read()}")
            with VmcSender([("127.0.0.1", json.loads(ready)["port"])]) as sender:
                sender.send(datagrams)
            out, err = process.communicate(timeout=10)
        assert process.returncode == 0, err
        return [json.loads(line) for line in out.splitlines()]

    return receive


def test_loopback_receives_every_bone(arm_raised: HumanoidMotion, loopback: Loopback) -> None:
    with VmcSender([("127.0.0.1", loopback.port)]) as sender:
        sender.send(vmc_frame(arm_raised, 1, time_s=12.5))
        messages = loopback.wait()
    assert sender.errors == {("127.0.0.1", loopback.port): 0}
    by_address = {address: args for address, args in messages}
    assert by_address["/VMC/Ext/Root/Pos"] == ["root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    assert by_address["/VMC/Ext/OK"] == [1]
    assert by_address["/VMC/Ext/T"] == [12.5]
    assert_frame(bone_values(messages), arm_raised, 1)


def test_raised_left_arm_points_to_unity_left_and_up(
    arm_raised: HumanoidMotion, loopback: Loopback
) -> None:
    with VmcSender([("127.0.0.1", loopback.port)]) as sender:
        sender.send(vmc_frame(arm_raised, 1, time_s=0.0))
        values = bone_values(loopback.wait())
    positions, rotations = unity_world(values)
    arm = positions[BONE_INDEX["LeftLowerArm"]] - positions[BONE_INDEX["LeftUpperArm"]]
    direction = arm / np.linalg.norm(arm)
    np.testing.assert_allclose(direction, [-np.sqrt(0.5), np.sqrt(0.5), 0.0], atol=1e-5)
    # the same direction from the bone's own world rotation and its rest bone (mirrored)
    rest_bone = values["LeftLowerArm"][:3]
    turned = rotations[BONE_INDEX["LeftUpperArm"]] @ rest_bone
    np.testing.assert_allclose(turned / np.linalg.norm(turned), direction, atol=1e-5)
    # the pelvis stays where the capture put it (+0.3 m to the subject's left -> Unity -X)
    assert values["Hips"][0] < -0.29
    assert values["LeftUpperLeg"][0] < 0 < values["RightUpperLeg"][0]


def test_npm_osc_decodes_every_bone(arm_raised: HumanoidMotion, osc_receive: Receive) -> None:
    bundles = vmc_frame(arm_raised, 1, time_s=3.25)
    decoded = osc_receive(bundles, len(FRAME_ADDRESSES))
    assert [m["address"] for m in decoded] == FRAME_ADDRESSES
    assert all(m["timeTag"] == [0, 1] for m in decoded)  # IMMEDIATELY
    assert sorted({m["size"] for m in decoded}) == sorted({len(b) for b in bundles})
    bones = [m for m in decoded if m["address"] == "/VMC/Ext/Bone/Pos"]
    assert [m["args"][0] for m in bones] == list(BONE_NAMES)
    assert {m["types"] for m in bones} == {"sfffffff"}
    assert decoded[0]["types"] == "sfffffff" and decoded[0]["args"][0] == "root"
    assert decoded[-2]["types"] == "i" and decoded[-2]["args"] == [1]
    assert decoded[-1]["types"] == "f" and decoded[-1]["args"] == [3.25]
    assert_frame({m["args"][0]: np.array(m["args"][1:]) for m in bones}, arm_raised, 1)


def test_every_bundle_fits_an_unfragmented_datagram() -> None:
    _, motion = synthetic_motion("walk", seconds=2.0)
    positions, rotations = unity_pose(motion)
    for frame in range(len(motion)):
        bundles = frame_bundles(positions[frame], rotations[frame], frame / motion.fps)
        assert all(len(b) <= min(MAX_BUNDLE_BYTES, 1472) for b in bundles)
        parsed = [OscBundle(b) for b in bundles]
        assert all(b[8:16] == b"\0" * 7 + b"\1" for b in bundles)  # timetag IMMEDIATELY
        addresses = [m.address for bundle in parsed for m in bundle]
        assert addresses == FRAME_ADDRESSES
    assert [len(b) for b in bundles] == [1392, 64]


def test_unreachable_targets_do_not_raise(arm_raised: HumanoidMotion, loopback: Loopback) -> None:
    closed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closed.bind(("127.0.0.1", 0))
    closed_port = closed.getsockname()[1]
    closed.close()
    refused = ("255.255.255.255", 39539)  # broadcast without SO_BROADCAST: EACCES
    live = ("127.0.0.1", loopback.port)
    bundles = vmc_frame(arm_raised, 0, time_s=0.0)
    with VmcSender([("127.0.0.1", closed_port), refused, live]) as sender:
        for _ in range(3):
            sender.send(bundles)
        loopback.wait()
    assert sender.errors[refused] == 3 * len(bundles)
    assert sender.errors[live] == 0


def test_bad_target_port_is_a_service_error() -> None:
    with pytest.raises(ServiceError, match="70000"):
        VmcSender([("127.0.0.1", 70000)])


def test_other_avatar_gets_its_own_bone_offsets(arm_raised: HumanoidMotion) -> None:
    avatar = HumanoidRig.from_body(Body.from_height(1.5), arm_angle_deg=40)
    positions, rotations = unity_pose(arm_raised, avatar)
    mirror = np.array([-1.0, 1.0, 1.0])
    for frame_positions in positions:
        np.testing.assert_allclose(frame_positions[1:], avatar.offsets[1:] * mirror)
    np.testing.assert_allclose(positions[:, 0], arm_raised.root * mirror)
    assert np.array_equal(unity_pose(arm_raised)[1], rotations)


def test_frame_bundles_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match=r"\(17, 3\)"):
        frame_bundles(np.zeros((13, 3)), np.zeros((13, 4)), 0.0)
