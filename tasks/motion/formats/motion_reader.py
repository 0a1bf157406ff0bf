"""One reader for every motion file type registered in :data:`~.registry.MOTION_FORMATS`, in metres
(``sm export``, ``sm view``, ``sm render``, ``sm evaluate-dance``):

- ``.npz``: our motion format (:mod:`.motion_file`); SMPL-24 through forward kinematics when no joints;
- ``.pkl``: an AIST++ motion (60 fps, read with the restricted unpickler), through forward kinematics;
- ``.npy``: joint positions (T, J, 3) or de-normalised HumanML3D features (T, 263) (:mod:`.joints_npy`);
- ``.bvh``: any BVH file (hierarchy from the file), its unit detected from the figure (:mod:`.units`);
- ``.skeleton``: a raw NTU RGB+D file (every tracked body, 30 fps);
- ``.glb``: a motion glTF as ``sm export`` writes it (:mod:`.gltf_read`).

:func:`load_joints` gives joint positions (:class:`JointsClip`), :func:`load_skeleton_motion` the joint tree
with rotations where the file has them (:class:`~.gltf.SkeletonMotion`). Both apply ``units`` / ``scale``
(:func:`~.units.choose_scale`) and carry the :class:`~.units.UnitScale` they used, for the commands to state.
"""

from __future__ import annotations

from dataclasses import replace
from os import PathLike
from pathlib import Path

from skeleton_mamba.tasks.motion.formats.gltf import (
    SkeletonMotion,
    check_skeleton_motion,
    from_joints,
    from_motion_data,
)
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.motion.formats.registry import MOTION_FORMATS, FileMotion, JointsClip, ReadRequest
from skeleton_mamba.tasks.motion.formats.units import choose_scale

__all__ = ["load_joints", "load_skeleton_motion"]


def _read(path: str | PathLike[str], skeleton: str | None, motion_fps: float | None) -> FileMotion:
    """The file's motion by its registered reader (``FileNotFoundError`` / ``ValueError`` naming the file)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such motion file")
    suffix = path.suffix.lower()
    if suffix not in MOTION_FORMATS:
        known = ", ".join(MOTION_FORMATS.names())
        raise ValueError(f"{path}: unsupported motion file type {suffix!r} ({known})")
    return MOTION_FORMATS.get(suffix).read(path, ReadRequest(skeleton, motion_fps))


def _as_skeleton_motion(
    path: Path, found: FileMotion, motion_fps: float | None, units: str | None, scale: float | None
) -> SkeletonMotion:
    """What a reader found as a joint tree in metres (:func:`load_skeleton_motion`)."""
    unit = choose_scale(units, scale, found.figure_height)
    motion = found.motion
    if isinstance(motion, MotionData):
        motion = from_motion_data(motion)
    elif isinstance(motion, JointsClip):
        motion = from_joints(motion.joints, None, motion.fps, motion.parents, motion.names)
    s = unit.metres_per_unit
    scaled = replace(
        motion,
        fps=motion_fps or motion.fps,
        offsets=motion.offsets * s,
        translations=motion.translations * s,
        scale=unit,
    )
    return check_skeleton_motion(scaled, str(path))  # what glTF cannot hold, refused naming the file


def load_skeleton_motion(
    path: str | PathLike[str],
    skeleton: str | None = None,
    motion_fps: float | None = None,
    units: str | None = None,
    scale: float | None = None,
) -> SkeletonMotion:
    """Any motion file (module docstring) as a joint tree in metres: rotations kept where the file has them
    (our SMPL ``.npz``, ``.pkl``, ``.bvh``, ``.glb``), joint positions as translations otherwise; checked as
    glTF needs it (:func:`~.gltf.check_skeleton_motion`: an :class:`~.errors.InputError` naming the file).

    Args:
        path: the motion file.
        skeleton: skeleton of a ``.npy`` joint file (else inferred from its joint count).
        motion_fps: the input's frame rate (replaces the file's).
        units: the input's length unit (:func:`~.units.choose_scale`).
        scale: the input's metres per unit, instead of ``units`` (:func:`~.units.choose_scale`).

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion
        >>> joints = np.zeros((4, 24, 3), np.float32)
        >>> joints[:, :, 1] = np.linspace(0.0, 1.7, 24)  # a standing column of joints, y up
        >>> path = Path(tempfile.mkdtemp()) / "clip.npz"
        >>> path = save_motion(path, MotionData(30.0, "smpl24", joints=joints))
        >>> motion = load_skeleton_motion(path)
        >>> motion.translations.shape, motion.rotations is None, motion.fps
        ((4, 24, 3), True, 30.0)
    """
    return _as_skeleton_motion(Path(path), _read(path, skeleton, None), motion_fps, units, scale)


def load_joints(
    path: str | PathLike[str],
    skeleton: str | None = None,
    motion_fps: float | None = None,
    units: str | None = None,
    scale: float | None = None,
) -> JointsClip:
    """Any motion file (module docstring) as joint positions in metres; arguments as
    :func:`load_skeleton_motion`.

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "clip.npy"  # joint positions (T, J, 3); 24 joints: SMPL-24
        >>> joints = np.zeros((4, 24, 3), np.float32)
        >>> joints[:, :, 1] = np.linspace(0.0, 1.7, 24)  # a standing column of joints, y up
        >>> np.save(path, joints)
        >>> clip = load_joints(path, motion_fps=30.0)
        >>> clip.joints.shape, clip.fps, len(clip.parents), clip.names[0]
        ((4, 24, 3), 30.0, 24, 'pelvis')
    """
    found = _read(path, skeleton, motion_fps)
    if isinstance(found.motion, SkeletonMotion):  # through the joint tree, checked as glTF needs it
        motion = _as_skeleton_motion(Path(path), found, motion_fps, units, scale)
        return JointsClip(motion.joint_positions(), motion.parents, motion.names, motion.fps, motion.scale)
    clip = found.motion
    if isinstance(clip, MotionData):
        clip = JointsClip.of_skeleton(clip.joint_positions(), clip.skeleton, clip.fps)
    unit = choose_scale(units, scale, found.figure_height)
    return replace(clip, joints=clip.joints * unit.metres_per_unit, fps=motion_fps or clip.fps, scale=unit)
