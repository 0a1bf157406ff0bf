"""Scenes and bodies of the EgoAIST++ builder tests."""

from __future__ import annotations

import numpy as np
import torch
import trimesh

from skeleton_mamba.tasks.egodance.builder.scene import make_scene
from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics_axis_angle

FEET = [7, 8, 10, 11]


def boxes_scene(boxes: list[tuple[list[float], list[float]]], name: str = "boxes"):
    """A y-up scene of axis-aligned boxes (lo, hi), grey."""
    parts = []
    for lo, hi in boxes:
        box = trimesh.creation.box(extents=np.subtract(hi, lo))
        box.apply_translation((np.add(lo, hi)) / 2)
        parts.append(box)
    mesh = trimesh.util.concatenate(parts)
    return make_scene(name, mesh.vertices, mesh.faces, np.full((len(mesh.vertices), 3), 200, np.uint8))


FLOOR = ([-5.0, -0.1, -5.0], [5.0, 0.0, 5.0])  # top face at y = 0


def rest_joints(frames: int = 4, root=(0.0, 0.93, 0.0)) -> np.ndarray:
    """(T, 24, 3) joints of the SMPL rest pose (T-pose) at ``root``, by the toolkit's FK."""
    poses = torch.zeros(frames, 24, 3, dtype=torch.float64)
    trans = torch.tensor(root, dtype=torch.float64).expand(frames, 3)
    return smpl_forward_kinematics_axis_angle(poses, trans).numpy()
