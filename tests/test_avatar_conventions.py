"""Any humanoid avatar drives: avatars named after Unity / VRM, Mixamo, Blender, Unreal
and Character Creator are read by the humanoid resolver, and on each a planted foot of
the source walk stays on the floor wherever the avatar's Hips joint sits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from samba.export import AVATAR_CONVENTIONS, write_named_avatar
from samba.export.avatar_file import read_avatar_rig
from samba.export.humanoid import BONE_INDEX, HumanoidRig
from samba.export.live_retarget import LiveRetarget
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import leg_length, retarget
from samba.synthetic.motions import generate

HIPS_ABOVE_LEGS = (-0.07, 0.0, 0.08, 0.25)


def _avatar(tmp_path: Path, convention: str, hips_dy: float) -> tuple[Path, HumanoidRig]:
    """A skeleton-only .glb of the mannequin with its Hips joint `hips_dy` meters above
    its leg joints, its nodes named after `convention`."""
    path = tmp_path / f"{convention.replace(' ', '_')}.glb"
    return path, write_named_avatar(path, convention, hips_dy)


@pytest.mark.parametrize("convention", list(AVATAR_CONVENTIONS))
def test_every_convention_drives_with_its_feet_on_the_floor(
    convention: str, tmp_path: Path
) -> None:
    take = generate("walk", seed=2, seconds=4.0)
    planted = take.poses[:, [11, 12], 1] < 0.001  # the synthetic walk plants at y = 0
    for hips_dy in HIPS_ABOVE_LEGS:
        path, built = _avatar(tmp_path, convention, hips_dy)
        rig = read_avatar_rig(path)
        np.testing.assert_allclose(rig.rest, built.rest, atol=1e-6)
        offline = retarget(take.poses, rig, take.fps)
        live = LiveRetarget(rig, leg_length=leg_length(take.poses))
        roots = np.stack([live.step(pose)[1] for pose in take.poses])
        for root in (offline.root, roots):
            motion = HumanoidMotion(rig, offline.rotations, root, take.fps)
            feet = motion.world_positions()[:, [BONE_INDEX["LeftFoot"], BONE_INDEX["RightFoot"]]]
            assert np.abs(feet[..., 1][planted] - rig.ankle_height).max() < 0.01, hips_dy
