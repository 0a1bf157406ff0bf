"""``sm render MOTION [--music FILE] --out clip.mp4|clip.gif [--fps N] [--skeleton NAME]``.

Reads any motion file the toolkit knows and renders a skeleton animation (see :mod:`.render`):

- ``.npz``: our motion format (:mod:`.motion_file`); SMPL-24 through forward kinematics when no joints;
- ``.pkl``: an AIST++ motion (60 fps, read with the restricted unpickler), through forward kinematics;
- ``.npy``: joint positions (T, J, 3); the skeleton is ``--skeleton`` or inferred from J
  (22 HumanML3D, 24 SMPL, 25 NTU, 18 OpenPose); its frame rate ``--motion-fps`` (default 20 for
  HumanML3D, 30 otherwise); or de-normalised HumanML3D features (T, 263) (``new_joint_vecs``,
  ``sm generate``'s ``*_features.npy``), turned into the 22 joints by ``recover_from_ric`` at 20 fps;
- ``.bvh``: any BVH file (hierarchy from the file);
- ``.skeleton``: a raw NTU RGB+D file (every tracked body, 30 fps).

``--fps`` resamples the joints linearly to the output frame rate (default: the motion's own).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.skeletons import get_skeleton
from skeleton_mamba.tasks.motion.aistpp import load_aistpp_motion
from skeleton_mamba.tasks.motion.bvh import load_bvh
from skeleton_mamba.tasks.motion.errors import InputError, one_line_message
from skeleton_mamba.tasks.motion.humanml3d_features import FEATURE_DIM, check_features, recover_from_ric
from skeleton_mamba.tasks.motion.humanml3d_features import FPS as HUMANML3D_FPS
from skeleton_mamba.tasks.motion.motion_file import load_motion
from skeleton_mamba.tasks.motion.ntu import read_skeleton_file
from skeleton_mamba.tasks.motion.render import render_motion
from skeleton_mamba.tasks.motion.render_args import build_parser
from skeleton_mamba.tasks.motion.resample import resample_linear
from skeleton_mamba.tasks.motion.value_checks import (
    MAX_POSITION_M,
    check_finite,
    check_fps,
    check_magnitude,
    load_npy,
)

__all__ = ["JointsClip", "load_joints", "render_file", "main"]

_BY_JOINT_COUNT = {22: "humanml3d22", 24: "smpl24", 25: "ntu25", 18: "openpose18"}
_DEFAULT_FPS = {"humanml3d22": 20.0}


@dataclass
class JointsClip:
    """Joint positions ready to draw: (T, J, 3) y-up, parents, names and frame rate."""

    joints: np.ndarray
    parents: list[int]
    names: list[str]
    fps: float


def _from_skeleton(joints: np.ndarray, skeleton: str, fps: float) -> JointsClip:
    skel = get_skeleton(skeleton)
    return JointsClip(joints, list(skel.parents), list(skel.joint_names), fps)


def load_joints(
    path: str | PathLike[str], skeleton: str | None = None, motion_fps: float | None = None
) -> JointsClip:
    """Read a motion file of any supported kind (see the module docstring) as joint positions."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such motion file")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        motion = load_motion(path)
        return _from_skeleton(motion.joint_positions(), motion.skeleton, motion_fps or motion.fps)
    if suffix == ".pkl":
        motion = load_aistpp_motion(path)
        return _from_skeleton(motion.joint_positions(), "smpl24", motion_fps or motion.fps)
    if suffix == ".npy":
        joints = load_npy(path)
        if joints.ndim == 2 and joints.shape[1] == FEATURE_DIM:
            features = torch.from_numpy(check_features(joints, path).astype(np.float64))
            joints = recover_from_ric(features).numpy()
            joints = check_finite(joints, f"{path} (joints recovered)", "joints", ("frame", "joint"))
            return _from_skeleton(joints, "humanml3d22", motion_fps or HUMANML3D_FPS)
        if joints.ndim != 3 or joints.shape[2] != 3:
            raise ValueError(
                f"{path}: expected joint positions (T, J, 3) or HumanML3D features (T, {FEATURE_DIM}), "
                f"got shape {joints.shape}"
            )
        name = skeleton or _BY_JOINT_COUNT.get(joints.shape[1])
        if name is None:
            raise ValueError(f"{path}: cannot infer a skeleton for {joints.shape[1]} joints; pass --skeleton")
        skel = get_skeleton(name)
        if skel.num_joints != joints.shape[1]:
            raise ValueError(f"{path}: {joints.shape[1]} joints, skeleton {skel.name} has {skel.num_joints}")
        if joints.shape[0] == 0:
            raise InputError(f"{path}: a joints file of zero frames")
        fps = motion_fps or _DEFAULT_FPS.get(skel.name, 30.0)
        joints = check_finite(joints.astype(np.float64), str(path), "joints", ("frame", "joint"))
        check_magnitude(joints, MAX_POSITION_M, str(path), "joints", ("frame", "joint"), unit=" m")
        return _from_skeleton(joints, name, fps)
    if suffix == ".bvh":
        bvh = load_bvh(path)
        return JointsClip(bvh.joint_positions(), list(bvh.parents), list(bvh.names), motion_fps or bvh.fps)
    if suffix == ".skeleton":
        keypoints = read_skeleton_file(path).keypoints(max_bodies=2)  # (M, T, 25, 3)
        if keypoints.shape[1] == 0:
            raise ValueError(f"{path}: no frame lists a body")
        skel = get_skeleton("ntu25")
        bodies = keypoints.shape[0]
        # Bodies side by side in one joint array; each keeps its own root (the camera follows the first).
        parents = [p + b * skel.num_joints if p >= 0 else -1 for b in range(bodies) for p in skel.parents]
        joints = np.concatenate(list(keypoints), axis=1).astype(np.float64)
        names = [n for _ in range(bodies) for n in skel.joint_names]
        return JointsClip(joints, parents, names, motion_fps or 30.0)
    raise ValueError(f"{path}: unsupported motion file type {suffix!r} (.npz, .pkl, .npy, .bvh, .skeleton)")


def render_file(
    motion: str | PathLike[str],
    out: str | PathLike[str],
    music: str | PathLike[str] | None = None,
    fps: float | None = None,
    skeleton: str | None = None,
    motion_fps: float | None = None,
    title: str | None = None,
    progress: bool = True,
) -> Path:
    """Load ``motion`` (any supported file), resample to ``fps`` if given, and render it to ``out``."""

    clip = load_joints(motion, skeleton=skeleton, motion_fps=motion_fps)
    joints, out_fps = clip.joints, check_fps(clip.fps, f"{motion}: motion frame rate")
    if fps is not None:
        check_fps(fps, "--fps")
    if fps is not None and abs(fps - clip.fps) > 1e-9:
        joints = resample_linear(torch.from_numpy(np.asarray(joints, np.float64)), clip.fps, fps).numpy()
        out_fps = fps
    return render_motion(
        joints, clip.parents, out, out_fps, music=music, names=clip.names, title=title, progress=progress
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm render``; returns 0 on success (bad input raises: `sm` prints one line)."""
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    start = time.perf_counter()
    try:
        out = render_file(
            args.motion,
            args.out,
            music=args.music,
            fps=args.fps,
            skeleton=args.skeleton,
            motion_fps=args.motion_fps,
            title=args.title if args.title is not None else Path(args.motion).name,
            progress=args.progress,
        )
    except (ValueError, KeyError) as e:  # the readers' argument checks name the file too: one line, exit 2
        raise InputError(one_line_message(e)) from e
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0
