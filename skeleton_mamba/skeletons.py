"""Skeleton definitions: joint names, kinematic parents, left/right mirror maps and tokenizer groups.

Every skeleton groups its joints into ``G = 5`` groups of ``P = 6`` joints for the Human Tokenizer,
ordered as in [EgoMusic] supp. Sec. 4: 0 spine and head, 1 right arm, 2 left arm,
3 right leg, 4 left leg. The arm and leg groups are mirror images of each other position by
position, so the group permutation 1<->2, 3<->4 is the body's left/right symmetry and the default
group-scan path set (:data:`DEFAULT_GROUP_PATHS`) is closed under it ([EgoMusic] supp. Eq. 20).

Only SMPL-24's grouping is published; the others follow the same pattern (a hub joint, then the
chain outwards) and are this project's choice.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "Skeleton",
    "SMPL24",
    "NTU25",
    "OPENPOSE18",
    "HUMANML3D22",
    "SKELETONS",
    "DEFAULT_GROUP_PATHS",
    "GROUP_MIRROR",
    "get_skeleton",
    "parents_first_order",
]

# The authors' eight group orders: arms, spine, legs or legs, spine, arms ([EgoMusic] code,
# Fsoft-AIC/SkeletonMamba ``model/skeleton_scans.py``).
DEFAULT_GROUP_PATHS: tuple[tuple[int, ...], ...] = (
    (1, 2, 0, 3, 4),
    (2, 1, 0, 3, 4),
    (1, 2, 0, 4, 3),
    (2, 1, 0, 4, 3),
    (3, 4, 0, 1, 2),
    (4, 3, 0, 1, 2),
    (3, 4, 0, 2, 1),
    (4, 3, 0, 2, 1),
)
# Left/right symmetry acting on the five groups.
GROUP_MIRROR: tuple[int, ...] = (0, 2, 1, 4, 3)


@dataclass(frozen=True)
class Skeleton:
    """A named skeleton.

    Attributes:
        name: registry key, e.g. ``"smpl24"``.
        joint_names: one name per joint, index order.
        parents: parent index per joint, ``-1`` for the root (a tree; not necessarily sorted).
        mirror: the joint index that each joint maps to under the left/right mirror.
        groups: ``G`` tuples of ``P`` joint indices for the Human Tokenizer (may overlap).

    Examples:
        >>> from skeleton_mamba import Skeleton
        >>> arm = Skeleton("arm", ("shoulder", "elbow", "wrist"), parents=(-1, 0, 1), mirror=(0, 1, 2),
        ...                groups=((0, 1), (1, 2)))
        >>> arm.parents, arm.groups
        ((-1, 0, 1), ((0, 1), (1, 2)))
    """

    name: str
    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    mirror: tuple[int, ...]
    groups: tuple[tuple[int, ...], ...]

    def __post_init__(self) -> None:
        j = len(self.joint_names)
        if len(self.parents) != j or len(self.mirror) != j:
            raise ValueError(f"{self.name}: parents/mirror must have one entry per joint ({j})")
        if sum(p < 0 for p in self.parents) != 1:
            raise ValueError(f"{self.name}: exactly one root (parent -1) is required")
        _ = self.topological_order  # raises on a cycle
        if sorted(self.mirror) != list(range(j)) or any(
            self.mirror[m] != i for i, m in enumerate(self.mirror)
        ):
            raise ValueError(f"{self.name}: mirror must be an involutive permutation")
        sizes = {len(g) for g in self.groups}
        if len(sizes) != 1:
            raise ValueError(f"{self.name}: all tokenizer groups must have the same size, got {sizes}")
        covered = {i for g in self.groups for i in g}
        if covered != set(range(j)):
            raise ValueError(f"{self.name}: groups miss joints {sorted(set(range(j)) - covered)}")

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def num_groups(self) -> int:
        return len(self.groups)

    @property
    def group_size(self) -> int:
        return len(self.groups[0])

    @property
    def group_paths(self) -> tuple[tuple[int, ...], ...]:
        """The default Group Scan paths: the authors' eight (:data:`DEFAULT_GROUP_PATHS`) for the five
        body groups (spine, arms, legs), else one path in group order."""
        if self.num_groups == len(GROUP_MIRROR):
            return DEFAULT_GROUP_PATHS
        return (tuple(range(self.num_groups)),)

    @property
    def topological_order(self) -> tuple[int, ...]:
        """Joint indices with every parent before its children (for forward kinematics)."""
        return parents_first_order(self.parents, self.name)

    def bones(self) -> list[tuple[int, int]]:
        """(parent, child) pairs, for drawing."""
        return [(p, i) for i, p in enumerate(self.parents) if p >= 0]

    def index(self, name: str) -> int:
        return self.joint_names.index(name)


def parents_first_order(parents: Sequence[int], name: str = "skeleton") -> tuple[int, ...]:
    """Joint indices with every parent before its children; raises ``ValueError`` on a cycle or a parent
    index out of range (any number of roots, ``-1``)."""
    if any(not -1 <= p < len(parents) for p in parents):
        raise ValueError(f"{name}: a parent index is out of range (0 to {len(parents) - 1}, or -1)")
    order: list[int] = []
    placed: set[int] = set()
    while len(order) < len(parents):
        ready = [i for i, p in enumerate(parents) if i not in placed and (p < 0 or p in placed)]
        if not ready:
            raise ValueError(f"{name}: parents contain a cycle")
        order += ready
        placed.update(ready)
    return tuple(order)


def _mirror_from_pairs(n: int, pairs: list[tuple[int, int]]) -> tuple[int, ...]:
    m = list(range(n))
    for a, b in pairs:
        m[a], m[b] = b, a
    return tuple(m)


SMPL24 = Skeleton(
    name="smpl24",
    joint_names=(
        "pelvis",
        "left_hip",
        "right_hip",
        "spine1",
        "left_knee",
        "right_knee",
        "spine2",
        "left_ankle",
        "right_ankle",
        "spine3",
        "left_foot",
        "right_foot",
        "neck",
        "left_collar",
        "right_collar",
        "head",
        "left_shoulder",
        "right_shoulder",
        "left_elbow",
        "right_elbow",
        "left_wrist",
        "right_wrist",
        "left_hand",
        "right_hand",
    ),
    parents=(-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21),
    mirror=_mirror_from_pairs(
        24, [(1, 2), (4, 5), (7, 8), (10, 11), (13, 14), (16, 17), (18, 19), (20, 21), (22, 23)]
    ),
    # [EgoMusic] supp. Sec. 4 (published).
    groups=(
        (0, 3, 6, 9, 12, 15),
        (9, 14, 17, 19, 21, 23),
        (9, 13, 16, 18, 20, 22),
        (0, 2, 3, 5, 8, 11),
        (0, 1, 3, 4, 7, 10),
    ),
)

HUMANML3D22 = Skeleton(
    name="humanml3d22",
    joint_names=SMPL24.joint_names[:22],
    parents=SMPL24.parents[:22],
    mirror=_mirror_from_pairs(22, [(1, 2), (4, 5), (7, 8), (10, 11), (13, 14), (16, 17), (18, 19), (20, 21)]),
    # SMPL-24's groups without the hands (22, 23): the arm groups start one joint lower (spine2).
    groups=(
        (0, 3, 6, 9, 12, 15),
        (6, 9, 14, 17, 19, 21),
        (6, 9, 13, 16, 18, 20),
        (0, 2, 3, 5, 8, 11),
        (0, 1, 3, 4, 7, 10),
    ),
)

NTU25 = Skeleton(
    name="ntu25",
    joint_names=(
        "spine_base",
        "spine_mid",
        "neck",
        "head",
        "left_shoulder",
        "left_elbow",
        "left_wrist",
        "left_hand",
        "right_shoulder",
        "right_elbow",
        "right_wrist",
        "right_hand",
        "left_hip",
        "left_knee",
        "left_ankle",
        "left_foot",
        "right_hip",
        "right_knee",
        "right_ankle",
        "right_foot",
        "spine_shoulder",
        "left_hand_tip",
        "left_thumb",
        "right_hand_tip",
        "right_thumb",
    ),
    # Kinect v2 hierarchy rooted at the spine base (0-based).
    parents=(-1, 0, 20, 2, 20, 4, 5, 6, 20, 8, 9, 10, 0, 12, 13, 14, 0, 16, 17, 18, 1, 7, 7, 11, 11),
    mirror=_mirror_from_pairs(
        25,
        [(4, 8), (5, 9), (6, 10), (7, 11), (12, 16), (13, 17), (14, 18), (15, 19), (21, 23), (22, 24)],
    ),
    # Kinect has five midline joints; the head fills the sixth slot of the spine group twice.
    groups=(
        (0, 1, 20, 2, 3, 3),
        (8, 9, 10, 11, 23, 24),
        (4, 5, 6, 7, 21, 22),
        (0, 16, 1, 17, 18, 19),
        (0, 12, 1, 13, 14, 15),
    ),
)

OPENPOSE18 = Skeleton(
    name="openpose18",
    joint_names=(
        "nose",
        "neck",
        "right_shoulder",
        "right_elbow",
        "right_wrist",
        "left_shoulder",
        "left_elbow",
        "left_wrist",
        "right_hip",
        "right_knee",
        "right_ankle",
        "left_hip",
        "left_knee",
        "left_ankle",
        "right_eye",
        "left_eye",
        "right_ear",
        "left_ear",
    ),
    # The ST-GCN Kinetics-skeleton layout, rooted at the neck; the nose hangs off the neck.
    parents=(1, -1, 1, 2, 3, 1, 5, 6, 1, 8, 9, 1, 11, 12, 0, 0, 14, 15),
    mirror=_mirror_from_pairs(18, [(2, 5), (3, 6), (4, 7), (8, 11), (9, 12), (10, 13), (14, 15), (16, 17)]),
    groups=(
        (1, 0, 14, 15, 16, 17),
        (0, 1, 2, 3, 4, 8),
        (0, 1, 5, 6, 7, 11),
        (1, 2, 8, 11, 9, 10),
        (1, 5, 11, 8, 12, 13),
    ),
)

SKELETONS: dict[str, Skeleton] = {s.name: s for s in (SMPL24, HUMANML3D22, NTU25, OPENPOSE18)}


def get_skeleton(skeleton: str | Skeleton) -> Skeleton:
    """Look a skeleton up by name (``smpl24``, ``humanml3d22``, ``ntu25``, ``openpose18``).

    Examples:
        >>> from skeleton_mamba import SKELETONS, get_skeleton
        >>> sorted(SKELETONS)  # the registered skeletons
        ['humanml3d22', 'ntu25', 'openpose18', 'smpl24']
        >>> smpl = get_skeleton("smpl24")
        >>> len(smpl.joint_names), [len(group) for group in smpl.groups]  # G = 5 groups of P = 6 joints
        (24, [6, 6, 6, 6, 6])
    """
    if isinstance(skeleton, Skeleton):
        return skeleton
    try:
        return SKELETONS[skeleton.lower()]
    except KeyError:
        raise KeyError(f"unknown skeleton {skeleton!r}; known: {sorted(SKELETONS)}") from None
