"""The SMPL body mesh of a motion window (``sm make-ego --smpl-model PATH``).

The builder's joints, placement and camera come from the toolkit's offset-table FK, which puts the pelvis
at the motion's root position. The mesh is posed by the user's SMPL model
(:mod:`skeleton_mamba.tasks.motion.body.smpl_model`, mean shape: AIST++ has no betas) and translated so that
its pelvis joint coincides with that root: ``trans = root - J_0`` (the SMPL model adds the rest pelvis
``J_0`` to ``trans``; the two skeletons then differ only by the model's slightly different bone lengths).

Each vertex is attached to the joint of its largest skinning weight (its *anchor*), which the mesh
penetration score uses (:func:`~.penetration.mesh_penetration_score`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from skeleton_mamba.tasks.motion.body.smpl_model import SMPLModel, load_smpl_model

__all__ = ["PosedBody", "pose_body", "get_body_model"]

_MODELS: dict[str, SMPLModel] = {}


def get_body_model(path: str) -> SMPLModel:
    """The SMPL model of ``path``, loaded once per process."""
    if path not in _MODELS:
        _MODELS[path] = load_smpl_model(path)
    return _MODELS[path]


@dataclass
class PosedBody:
    """A posed mesh sequence in the motion's frame (before placement).

    Attributes:
        vertices: (T, V, 3) float64 metres.
        joints: (T, 24, 3) the model's posed joints (its pelvis at the motion's root position).
        anchor: (V,) joint index of each vertex's largest skinning weight.
    """

    vertices: np.ndarray
    joints: np.ndarray
    anchor: np.ndarray


def pose_body(model: SMPLModel, poses: torch.Tensor, root: torch.Tensor, chunk: int = 32) -> PosedBody:
    """Pose the mean-shape mesh for every frame (``chunk`` frames at a time to bound memory).

    Args:
        model: the SMPL model.
        poses: (T, 24, 3) axis-angle SMPL poses.
        root: (T, 3) pelvis positions (the offset-table FK root).
    """
    trans = root.to(model.v_template) - model.rest_joints()[0]
    vertices, joints = [], []
    with torch.no_grad():
        for start in range(0, len(poses), chunk):
            v, j = model(poses[start : start + chunk], trans=trans[start : start + chunk])
            vertices.append(v.numpy())
            joints.append(j.numpy())
    anchor = model.weights.argmax(dim=1).numpy()
    return PosedBody(np.concatenate(vertices), np.concatenate(joints), anchor)
