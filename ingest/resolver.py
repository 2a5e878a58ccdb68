"""The humanoid resolver: which joint of a skeleton nobody told us about is each humanoid
bone, from its joint names and its tree together.

Both ends use it: `samba db import` maps a BVH rig to Samba's 13 joints
(`samba.ingest.rigs`), `samba export` and `samba serve` find an avatar's humanoid bones
(`samba.export.read_avatar_rig`).

* **Names** are tokenised (separators `_ . : - space`, camelCase, digits) after dropping
  namespace and tool prefixes (`mixamorig:`, `CC_Base_`, `Bip01 `, `DEF-`, ...); a side
  is a first or last token `L`, `R`, `Left`, `Right` (any case); the rest names a bone
  through synonyms (upper arm / arm / humerus, forearm / lower arm / elbow, hand / wrist,
  thigh / up leg / upper leg / femur, shin / calf / leg / knee, foot / ankle, ...). Twist,
  roll and share bones, finger and toe bones and End Sites are recognised as such.
* **Structure**: each limb is the chain from its end (hand, foot) up to where it meets
  the other limb of its pair (the chest, the pelvis); twist bones are passed over, and
  counted from the end the chain holds the hand or foot, the lower and the upper bone,
  and above them the clavicle or the leg's root bone. The head is on the third branch of
  the chest. When names give no hand or foot, the ends are the tips of the tree's five
  long branches (the head and the hands share a branch point), and left and right come
  from the rest pose's geometry (up the spine, forward along the feet).
* **Both**: a joint the structure places where its name says another bone is a
  conflict, and a tree that is not a humanoid's (legs along the spine, no arms, six long
  branches) is refused; the error says which limb could not be placed.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from samba.ingest.errors import RigError

SIDES = ("Left", "Right")
LIMB_BONES = {
    "arm": ("Shoulder", "UpperArm", "LowerArm", "Hand"),
    "leg": ("LegRoot", "UpperLeg", "LowerLeg", "Foot"),
}
"""A limb's bones from the trunk to its end (`Shoulder` is the clavicle, `LegRoot` a
bone from the pelvis to the hip joint, as CMU's `LHipJoint`; both optional)."""
CAPTURE_BONES: tuple[str, ...] = (
    "Head",
    "LeftUpperArm",
    "RightUpperArm",
    "LeftLowerArm",
    "RightLowerArm",
    "LeftHand",
    "RightHand",
    "LeftUpperLeg",
    "RightUpperLeg",
    "LeftLowerLeg",
    "RightLowerLeg",
    "LeftFoot",
    "RightFoot",
)
"""The bone at each of Samba's 13 joints, in `samba.body.JOINT_NAMES` order."""
LONG_BRANCH = 0.15
"""A branch is a limb when it reaches this fraction of the skeleton's extent."""

_PREFIXES = re.compile(r"^(mixamorig\d*[:_]?|cc_base_|rl_|bip\d*[ _]|def[-_]|org[-_]|mch[-_])")
_TOKENS = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|\d+")
_LEFT, _RIGHT = {"l", "left", "lft"}, {"r", "right", "rt"}
_KINDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("end", ("end", "nub", "top", "site", "tip")),
    ("twist", ("twist", "roll", "share", "helper", "corrective")),
    (
        "finger",
        (
            "thumb",
            "index",
            "middle",
            "mid",
            "ring",
            "pinky",
            "little",
            "finger",
            "carpal",
            "metacarpal",
        ),
    ),
    ("toe", ("toe", "toes", "toebase", "ball")),
    ("hand", ("hand", "wrist", "palm")),
    ("lowerarm", ("forearm", "lowerarm", "lowarm", "elbow", "radius", "ulna")),
    ("upperarm", ("upperarm", "uparm", "humerus", "arm")),
    ("shoulder", ("shoulder", "shldr")),
    ("clavicle", ("clavicle", "collar", "clav", "scapula")),
    ("foot", ("foot", "ankle")),
    ("lowerleg", ("lowerleg", "lowleg", "shin", "calf", "knee", "crus", "leg")),
    ("upperleg", ("upperleg", "upleg", "thigh", "femur")),
    ("legroot", ("hipjoint", "buttock")),
    ("hips", ("hips", "pelvis", "hip")),
    (
        "spine",
        (
            "spine",
            "abdomen",
            "waist",
            "lowerback",
            "torso",
            "back",
            "chest",
            "upperchest",
            "upperback",
        ),
    ),
    ("neck", ("neck", "lowerneck", "upperneck")),
    ("head", ("head",)),
)
"""Bone kinds and the words that name them, tried in order on a name's joined tokens
(`hip` with a side is an upper leg, without one the pelvis)."""
_KIND_WORDS = {
    "end": "end of a chain",
    "twist": "twist bone",
    "finger": "fingers",
    "toe": "toes",
    "hand": "hand",
    "lowerarm": "lower arm",
    "upperarm": "upper arm",
    "shoulder": "shoulder",
    "clavicle": "clavicle",
    "foot": "foot",
    "lowerleg": "lower leg",
    "upperleg": "upper leg",
    "legroot": "hip bone",
    "hips": "hips",
    "spine": "spine",
    "neck": "neck",
    "head": "head",
}
"""Each bone kind in words, for errors."""
_GENERIC = {"bone", "bn", "jnt", "joint", "bend", "def"}
"""Words that name no bone ("Bone_L_Arm", "jnt_knee"; Daz's "Bend" joints are the bones)."""
_SERIES = {"upperarm", "lowerarm", "upperleg", "lowerleg", "shoulder", "hand", "foot"}
"""Limb kinds that a digit turns into a numbered series along the limb ("Arm1", "Arm2")."""
_ACCEPTS: dict[str, set[str | None]] = {
    "Shoulder": {None, "clavicle", "shoulder"},
    "UpperArm": {None, "upperarm", "shoulder"},
    "LowerArm": {None, "lowerarm"},
    "Hand": {None, "hand"},
    "LegRoot": {None, "legroot", "hips", "upperleg"},
    "UpperLeg": {None, "upperleg"},
    "LowerLeg": {None, "lowerleg"},
    "Foot": {None, "foot"},
    "Head": {None, "head"},
}
"""Name kinds a joint may carry where the structure places each bone."""


@dataclass(frozen=True)
class SkeletonTree:
    """A skeleton as the resolver sees it: joint `names`, `parents` (-1 for a root) and
    rest `positions` (n, 3) in any unit and frame."""

    names: tuple[str, ...]
    parents: tuple[int, ...]
    positions: np.ndarray


@dataclass(frozen=True)
class NameKind:
    """What a joint name says: `side` ("Left", "Right" or None) and `kind` (a key of the
    kinds table, or None when the name says nothing)."""

    side: str | None
    kind: str | None


@dataclass(frozen=True)
class HumanoidMap:
    """Where each humanoid bone is: `bones` maps Unity humanoid names (`Hips`, `Spine`,
    `Chest`, `Neck`, `Head`, `LeftShoulder`, `LeftUpperArm`, ..., `LeftFoot`, ...) to joint
    indices of `tree`, `evidence` says per bone what placed it ("name and structure",
    "structure", or "name" for the spine bones)."""

    tree: SkeletonTree
    bones: dict[str, int]
    evidence: dict[str, str]

    @property
    def capture_joints(self) -> list[int]:
        """Joint indices of Samba's 13 joints, in `samba.body.JOINT_NAMES` order."""
        return [self.bones[bone] for bone in CAPTURE_BONES]

    def report(self) -> str:
        """The mapping as a table: bone, joint name, evidence."""
        rows = [(bone, self.tree.names[i], self.evidence[bone]) for bone, i in self.bones.items()]
        width = max(len(r[0]) for r in rows), max(len(r[1]) for r in rows)
        return "\n".join(f"{b:<{width[0]}}  {n:<{width[1]}}  {e}" for b, n, e in rows)


def name_kind(name: str) -> NameKind:
    """What the joint name `name` says of its side and bone."""
    parts = re.split(r"[_.\-\s]+", _unprefixed(name))
    words = [w.lower() for part in parts for w in _TOKENS.findall(part)]
    words = [w for w in words if w not in _GENERIC]  # Daz's "lShldrBend" is the shoulder
    side = None
    sided = [i for i, w in enumerate(words) if w in _LEFT | _RIGHT]
    ends = [i for i in sided if i in (0, len(words) - 1)]
    pick = ends[:1] or (sided if len(sided) == 1 else [])  # "Bone_L_Arm1": a side inside
    if pick and len(words) > 1:
        side = "Left" if words.pop(pick[0]) in _LEFT else "Right"
    joined = "".join(w for w in words if not w.isdigit())
    kind = _kind(words, joined)
    if kind in _SERIES and any(w.isdigit() for w in words):
        kind = None  # "Arm1", "Arm2": numbered segments of a limb, placed by structure
    if kind is None and side is None:  # one lower-case word: "lefthand", "rshin"
        for prefix, named in (("left", "Left"), ("right", "Right"), ("l", "Left"), ("r", "Right")):
            rest = joined.removeprefix(prefix)
            if rest != joined and _kind([rest], rest) not in (None, "end", "twist", "finger"):
                side, joined, kind = named, rest, _kind([rest], rest)
                break
    if kind == "hips" and side is not None:
        kind = "upperleg"  # "LeftHip" is the hip joint of a leg, "hip" alone the pelvis
    return NameKind(side, kind)


def _kind(words: list[str], joined: str) -> str | None:
    """The bone kind of a name's words (side taken off) and their digit-free join."""
    for kind, keys in _KINDS:
        if kind in ("end", "twist", "finger"):
            if any(key in words or (len(key) > 3 and key in joined) for key in keys):
                return kind
        elif joined in keys:
            return kind
    return None


def _unprefixed(name: str) -> str:
    """`name` without a "namespace:" and a tool prefix (case kept for camelCase)."""
    name = name.rsplit(":", 1)[-1].strip()
    match = _PREFIXES.match(name.lower())
    return name[match.end() :] if match else name


def resolve_humanoid(tree: SkeletonTree, source: str) -> HumanoidMap:
    """The humanoid bones of `tree` (see the module's docstring). Raises `RigError`
    naming `source` and the limb that could not be placed when the tree is not a
    humanoid's or its names contradict its structure."""
    return _Resolution(tree, source).run()


class _Resolution:
    """One run of `resolve_humanoid` over one tree."""

    def __init__(self, tree: SkeletonTree, source: str) -> None:
        self.tree, self.source = tree, source
        self.n = len(tree.names)
        self.kinds = [name_kind(n) for n in tree.names]
        self.positions = np.asarray(tree.positions, dtype=np.float64)
        self.children: list[list[int]] = [[] for _ in range(self.n)]
        for j, p in enumerate(tree.parents):
            if p >= 0:
                self.children[p].append(j)
        extent = self.positions.max(axis=0) - self.positions.min(axis=0) if self.n else [0.0]
        self.size = float(np.max(extent))

    def fail(self, problem: str) -> RigError:
        """The error naming the source: not a humanoid, and why."""
        return RigError(self.source, f"not a humanoid skeleton: {problem}")

    def run(self) -> HumanoidMap:
        """Ends, chains, trunk, checks."""
        if self.n < 8:
            raise self.fail(f"{self.n} joints, too few for arms, legs and a head")
        if not self.size > 0:
            raise self.fail("its joints all stand at one point (scaled to nothing?)")
        ends, unnamed = self._named_ends()
        if unnamed:
            try:
                ends = self._structural_ends()
            except RigError as exc:  # say what the names lacked as well
                where = " and ".join(_words(bone) for bone in unnamed)
                problem = exc.problem.removeprefix("not a humanoid skeleton: ")
                raise self.fail(f"no joint is named for the {where}, and {problem}") from None
        bones: dict[str, int] = {}
        evidence: dict[str, str] = {}
        for limb, pair in (("arm", "Hand"), ("leg", "Foot")):
            left, right = ends[f"Left{pair}"], ends[f"Right{pair}"]
            top = self._common_ancestor(left, right)
            for side, end in (("Left", left), ("Right", right)):
                chain = self._chain(end, top, side, limb)
                for bone, joint in zip(reversed(LIMB_BONES[limb]), reversed(chain), strict=False):
                    bones[side + bone] = joint
            bones["Chest" if limb == "arm" else "Hips"] = top
        hands = (ends["LeftHand"], ends["RightHand"])
        head = self._head(bones["Chest"], ends.get("Head"), hands)
        bones["Head"] = head
        self._check_geometry(bones)
        self._spine(bones)
        for bone, joint in bones.items():
            evidence[bone] = self._evidence(bone, joint)
        order = ["Hips", "Spine", "Chest", "Neck", "Head"]
        order += [s + b for s in SIDES for b in LIMB_BONES["arm"]]
        order += [s + b for s in SIDES for b in LIMB_BONES["leg"]]
        ordered = {b: bones[b] for b in order if b in bones}
        return HumanoidMap(self.tree, ordered, {b: evidence[b] for b in ordered})

    # -- the limbs' ends ---------------------------------------------------------------

    def _named_ends(self) -> tuple[dict[str, int], list[str]]:
        """Hands and feet (and the head) by name, per side the named one nearest the root,
        and the hands and feet no name gives."""
        ends: dict[str, int] = {}
        unnamed = []
        for kind, bone in (("hand", "Hand"), ("foot", "Foot")):
            for side in SIDES:
                found = [j for j, k in enumerate(self.kinds) if k.kind == kind and k.side == side]
                if found:
                    ends[side + bone] = min(found, key=self._depth)
                else:
                    unnamed.append(side + bone)
        heads = [j for j, k in enumerate(self.kinds) if k.kind == "head"]
        if heads:
            ends["Head"] = min(heads, key=self._depth)
        return ends, unnamed

    def _structural_ends(self) -> dict[str, int]:
        """The five limb ends from the tree alone: the tips of its long branches, the head
        and the hands below one branch point, the feet below another."""
        reach = self._reach()
        tips, stack = [], [j for j in range(self.n) if self.tree.parents[j] < 0]
        while stack:  # down the long branches only
            j = stack.pop()
            longer = self._long_children(j, reach)
            stack.extend(longer)
            if not longer and self.tree.parents[j] >= 0:
                tips.append(self.tree.parents[j] if self.kinds[j].kind == "end" else j)
        if len(tips) != 5:
            raise self.fail(
                f"its tree has {len(tips)} long branches where a humanoid has 5 (head, two "
                "arms, two legs)"
            )
        top = tips[0]
        for tip in tips[1:]:
            top = self._common_ancestor(top, tip)
        groups: dict[int, list[int]] = {}
        for tip in tips:
            groups.setdefault(self._child_towards(top, tip), []).append(tip)
        upper = [g for g in groups.values() if len(g) == 3]
        if len(upper) != 1:
            raise self.fail("no branch point carries the head and two arms")
        upper_body = upper[0]
        feet = [t for t in tips if t not in upper_body]
        chest = self._common_ancestor(*upper_body[:2])
        chest = self._common_ancestor(chest, upper_body[2])
        axis = self.positions[chest] - self.positions[top]
        head = max(upper_body, key=lambda t: _cos(self.positions[t] - self.positions[chest], axis))
        hands = [t for t in upper_body if t != head]
        left_hand, right_hand = self._sides(hands, feet, axis)
        left_foot, right_foot = self._sides(feet, feet, axis)
        return {
            "LeftHand": left_hand,
            "RightHand": right_hand,
            "LeftFoot": left_foot,
            "RightFoot": right_foot,
        }

    def _sides(self, pair: list[int], feet: list[int], up: np.ndarray) -> tuple[int, int]:
        """(left, right) of two limb ends: by the names along their chains, else by the
        rest pose (left = up x forward, forward along the feet's children)."""
        votes = []
        for end in pair:
            sides = [self.kinds[j].side for j in self._ancestors(end)[:4] if self.kinds[j].side]
            votes.append(sides[0] if sides else None)
        if set(votes) in ({"Left", "Right"}, {"Left", None}, {"Right", None}):
            first_left = votes[0] == "Left" or votes[1] == "Right"
            return (pair[0], pair[1]) if first_left else (pair[1], pair[0])
        toes = [c for f in feet for c in self.children[f]]
        if not toes:
            raise self.fail(
                "left and right cannot be told apart: no side in the names and "
                "no toes to show which way the feet point"
            )
        forward = np.mean(
            [self.positions[c] - self.positions[self.tree.parents[c]] for c in toes], axis=0
        )
        left_axis = np.cross(up, forward)
        a, b = pair
        top = self._common_ancestor(a, b)  # compare where the limbs leave the trunk: in a
        roots = [self.positions[self._child_towards(top, e)] for e in pair]  # stride the
        left = a if np.dot(roots[0] - roots[1], left_axis) > 0 else b  # feet are front-back
        return left, (b if left == a else a)

    # -- chains ----------------------------------------------------------------------------

    def _chain(self, end: int, top: int, side: str, limb: str) -> list[int]:
        """The joints of a limb from below `top` down to `end`, twist bones left out;
        `RigError` when it holds fewer than the end, lower and upper bones."""
        path = []
        j = end
        while j != top:
            if j < 0:
                raise self.fail(f"the {side.lower()} {limb} does not hang from the trunk")
            if self.kinds[j].kind not in ("twist", "end"):
                path.append(j)
            j = self.tree.parents[j]
        path.reverse()
        if len(path) < 3:
            raise self.fail(
                f"the {side.lower()} {limb} has {len(path)} bones between the trunk and "
                f"{self.tree.names[end]!r}; it needs an upper, a lower bone and the end"
            )
        return path[-4:]

    def _head(self, chest: int, named: int | None, hands: tuple[int, int]) -> int:
        """The head: the named head below the chest, else down the chest's long branch
        that leads to neither hand, through joints with one child (End Sites and twist
        bones aside), to the first that ends or branches (eyes, jaw, face bones) or whose
        one child sits on it (a face root at the head joint)."""
        if named is not None and chest in self._ancestors(named):
            return named
        reach = self._reach()
        arms = {self._child_towards(chest, hand) for hand in hands}
        branches = [c for c in self._long_children(chest, reach) if c not in arms]
        if not branches:
            raise self.fail("no head: the chest carries only the arms")
        j = max(branches, key=lambda c: reach[c])
        while True:
            below = [c for c in self.children[j] if self.kinds[c].kind != "end"]
            if len(below) != 1:
                return j
            if np.linalg.norm(self.positions[below[0]] - self.positions[j]) < 0.005 * self.size:
                return j
            j = below[0]

    def _spine(self, bones: dict[str, int]) -> None:
        """Spine, Chest and Neck by name, in place: on the trunk from the hips' branch
        point up to the arms' (the structural chest, which leaves `bones` unless it is
        named), the first spine bone, the first named chest after it ("chest", "spine1") or
        else the second spine bone, and the neck bone nearest the head."""
        chest, head = bones.pop("Chest"), bones["Head"]
        above_hips = {bones["Hips"], *self._ancestors(bones["Hips"])}
        trunk = []
        j = chest
        while j >= 0 and j not in above_hips:
            trunk.append(j)
            j = self.tree.parents[j]
        trunk.reverse()
        spine = [j for j in trunk if self.kinds[j].kind == "spine"]
        if spine:
            bones["Spine"] = spine[0]
        chests = [j for j in spine[1:] if _is_chest(self.tree.names[j])] or spine[1:2]
        if chests:  # a bone named chest ("spine1" after "spine"), else the second spine bone
            bones["Chest"] = chests[0]
        neck = [j for j in self._ancestors(head) if self.kinds[j].kind == "neck"]
        if neck:
            bones["Neck"] = neck[0]

    # -- checks --------------------------------------------------------------------------

    def _check_geometry(self, bones: dict[str, int]) -> None:
        """Legs hang away from the chest, and names agree with the places."""
        hips, chest = self.positions[bones["Hips"]], self.positions[bones["Chest"]]
        if np.linalg.norm(chest - hips) <= 1e-9 * self.size:
            raise self.fail("the legs and the arms meet at one joint: there is no trunk")
        for side in SIDES:
            foot = self.positions[bones[side + "Foot"]]
            if _cos(foot - hips, chest - hips) > -0.3:
                raise self.fail(
                    f"the {side.lower()} leg does not hang away from the chest (it runs along "
                    "or across the trunk: a four-legged or lying rig?)"
                )
        for bone, joint in bones.items():
            role = bone.removeprefix("Left").removeprefix("Right")
            kind = self.kinds[joint]
            side = bone[: len(bone) - len(role)] or None
            if role in _ACCEPTS and kind.kind not in _ACCEPTS[role]:
                raise self.fail(
                    f"{self.tree.names[joint]!r} is named for the {_KIND_WORDS[kind.kind]} but "
                    f"stands where the {_words(bone)} is"
                )
            if side and kind.side and kind.side != side and role in _ACCEPTS:
                raise self.fail(
                    f"{self.tree.names[joint]!r} is named {kind.side.lower()} but stands on "
                    f"the {side.lower()} side's chain"
                )

    def _evidence(self, bone: str, joint: int) -> str:
        """How `joint` was placed as `bone`."""
        role = bone.removeprefix("Left").removeprefix("Right")
        if role in ("Spine", "Chest", "Neck"):
            return "name"
        return "name and structure" if self.kinds[joint].kind else "structure"

    # -- tree helpers ----------------------------------------------------------------------

    def _ancestors(self, j: int) -> list[int]:
        """Ancestors of `j`, nearest first."""
        out = []
        p = self.tree.parents[j]
        while p >= 0:
            out.append(p)
            p = self.tree.parents[p]
        return out

    def _depth(self, j: int) -> int:
        return len(self._ancestors(j))

    def _common_ancestor(self, a: int, b: int) -> int:
        """The lowest common ancestor of `a` and `b` (one of them if it holds the other)."""
        above = {a, *self._ancestors(a)}
        for j in [b, *self._ancestors(b)]:
            if j in above:
                return j
        raise self.fail(f"{self.tree.names[a]!r} and {self.tree.names[b]!r} are in separate trees")

    def _child_towards(self, top: int, j: int) -> int:
        """The child of `top` on the way down to `j` (`j` itself if `top` is its parent)."""
        while self.tree.parents[j] != top:
            j = self.tree.parents[j]
        return j

    def _reach(self) -> np.ndarray:
        """Per joint, the longest path (rest lengths) down to any joint below it."""
        reach = np.zeros(self.n)
        for j in sorted(range(self.n), key=self._depth, reverse=True):  # children first
            p = self.tree.parents[j]
            if p >= 0:
                length = np.linalg.norm(self.positions[j] - self.positions[p])
                reach[p] = max(reach[p], reach[j] + length)
        return reach

    def _long_children(self, j: int, reach: np.ndarray) -> list[int]:
        """Children of `j` whose branch reaches `LONG_BRANCH` of the skeleton's size."""
        threshold = LONG_BRANCH * self.size
        return [
            c
            for c in self.children[j]
            if reach[c] + np.linalg.norm(self.positions[c] - self.positions[j]) >= threshold
        ]


def _is_chest(name: str) -> bool:
    """Whether a spine bone's name makes it the chest: "chest", or "spine1"/"spine01"."""
    plain = re.sub(r"[^a-z0-9]", "", _unprefixed(name).lower())
    return "chest" in plain or re.fullmatch(r"spine0?1", plain) is not None


def _cos(a: np.ndarray, b: np.ndarray) -> float:
    """Cosine of the angle between vectors `a` and `b` (0 for a zero vector)."""
    norm = float(np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.dot(a, b)) / norm if norm > 0 else 0.0


def _words(bone: str) -> str:
    """A bone name in words: "LeftUpperArm" -> "left upper arm"."""
    return " ".join(w.lower() for w in re.findall(r"[A-Z][a-z]*", bone))


def tree_of_offsets(
    names: Sequence[str], parents: Sequence[int], offsets: np.ndarray
) -> SkeletonTree:
    """The `SkeletonTree` of a hierarchy given by rest offsets (n, 3) from each joint's
    parent (a root's: its position), as BVH writes it."""
    positions = np.array(offsets, dtype=np.float64)
    for j, p in enumerate(parents):
        if p >= 0:
            positions[j] = positions[j] + positions[p]
    return SkeletonTree(tuple(names), tuple(parents), positions)
