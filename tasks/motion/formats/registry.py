"""The motion file types the toolkit reads, by suffix: :data:`MOTION_FORMATS`, a
:class:`~skeleton_mamba.registry.Registry` of :class:`MotionFormat` readers.

Each format's module registers its reader where it defines the format, in one line::

    @MOTION_FORMATS.register(".bvh")
    def read_bvh_motion(path: Path, request: ReadRequest) -> FileMotion: ...

and :mod:`.motion_reader` (``sm export``, ``sm view``, ``sm render``, ``sm retarget``) reads any registered
suffix. A new format is one module holding its reader, and its name in :data:`FORMAT_MODULES` (imported on
the first lookup, as mmengine's ``locations``); a format defined outside this package registers the same way
from a module imported before the file is read.

A reader returns what the file holds, in the file's own units (:class:`FileMotion`): an SMPL motion
(:class:`~.motion_file.MotionData`), a joint tree with rotations (:class:`~.gltf.SkeletonMotion`), or joint
positions (:class:`JointsClip`); :mod:`.motion_reader` makes either view of it and applies the units.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Union

import numpy as np

from skeleton_mamba.registry import Registry
from skeleton_mamba.skeletons import get_skeleton
from skeleton_mamba.tasks.motion.formats.units import METRES, UnitScale

if TYPE_CHECKING:
    from skeleton_mamba.tasks.motion.formats.gltf import SkeletonMotion
    from skeleton_mamba.tasks.motion.formats.motion_file import MotionData

__all__ = ["FORMAT_MODULES", "MOTION_FORMATS", "FileMotion", "JointsClip", "MotionFormat", "ReadRequest"]

FORMAT_MODULES = (
    "skeleton_mamba.tasks.motion.formats.motion_file",  # .npz
    "skeleton_mamba.tasks.motion.formats.aistpp",  # .pkl
    "skeleton_mamba.tasks.motion.formats.joints_npy",  # .npy
    "skeleton_mamba.tasks.motion.formats.bvh",  # .bvh
    "skeleton_mamba.tasks.motion.formats.ntu",  # .skeleton
    "skeleton_mamba.tasks.motion.formats.gltf_read",  # .glb
)
"""The modules whose readers register the built-in formats (imported on the first lookup)."""


@dataclass
class JointsClip:
    """Joint positions ready to draw: (T, J, 3) metres y-up, parents, names, frame rate, the scale applied."""

    joints: np.ndarray
    parents: list[int]
    names: list[str]
    fps: float
    scale: UnitScale = METRES

    @classmethod
    def of_skeleton(cls, joints: np.ndarray, skeleton: str, fps: float) -> JointsClip:
        """Joints (T, J, 3) of the named skeleton (:func:`~skeleton_mamba.skeletons.get_skeleton`): its
        parents and joint names."""
        skel = get_skeleton(skeleton)
        return cls(joints, list(skel.parents), list(skel.joint_names), fps)


@dataclass(frozen=True)
class ReadRequest:
    """What the command line says of a file that the file may not say itself.

    Args:
        skeleton: the skeleton of a joint-positions file (``None``: the reader infers it).
        motion_fps: the file's frame rate (``None``: the file's, or the format's default).
    """

    skeleton: str | None = None
    motion_fps: float | None = None


@dataclass
class FileMotion:
    """What a reader found: the motion in the file's units, and the figure's height in those units where the
    format's unit is detected from it (BVH: :func:`~.units.choose_scale`), else ``None`` (metres)."""

    motion: Union[MotionData, SkeletonMotion, JointsClip]
    figure_height: float | None = None


@dataclass(frozen=True)
class MotionFormat:
    """One registered file type: ``read(path, request) -> FileMotion``; ``reads`` names it in messages."""

    read: Callable[[Path, ReadRequest], FileMotion]
    reads: str


class _FormatRegistry(Registry[MotionFormat]):
    """:class:`~skeleton_mamba.registry.Registry` whose ``register`` wraps a reader function in a
    :class:`MotionFormat` (its first docstring line says what it reads)."""

    def register(self, name: str, *, force: bool = False) -> Callable:
        if not name.startswith(".") or name != name.lower():
            raise ValueError(f"a motion format is registered by its lower-case suffix ('.bvh'), got {name!r}")
        add = super().register(name, force=force)

        def wrap(read: Callable[[Path, ReadRequest], FileMotion]) -> Callable:
            add(MotionFormat(read, (read.__doc__ or name).strip().splitlines()[0]))
            return read

        return wrap


MOTION_FORMATS: Registry[MotionFormat] = _FormatRegistry("motion file type", locations=FORMAT_MODULES)
"""Every readable motion file type, by lower-case suffix."""
