"""A tiny SMPL body model file for tests."""

from __future__ import annotations

import numpy as np

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.body.smpl import SMPL_REST_OFFSETS

# 4 corners of a small tetrahedron around each joint; they sum to zero, so their mean is the joint
TETRA = 0.02 * np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])


TETRA_FACES = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])


BLENDED = 96  # index of the extra vertex weighted half to the left shoulder (16), half to the elbow (18)


def rest_joint_positions(pelvis=(0.0, 0.2, 0.0)) -> np.ndarray:
    """(24, 3) rest joints: the toolkit's rest offsets accumulated along the SMPL-24 tree."""
    joints = np.zeros((24, 3))
    joints[0] = pelvis
    for j in range(1, 24):
        joints[j] = joints[SMPL24.parents[j]] + SMPL_REST_OFFSETS[j]
    return joints


def tiny_model_arrays(num_betas: int = 3, pose_blend: bool = True, seed: int = 0) -> dict[str, np.ndarray]:
    """A 97-vertex SMPL-format model: a tetrahedron of 4 vertices on every joint, fully weighted to it
    (its regressor row averages them, so the regressed joints are the tetrahedra centres), plus one
    vertex between shoulder and elbow weighted half to each."""
    rng = np.random.default_rng(seed)
    joints = rest_joint_positions()
    v_template = np.concatenate([(joints[:, None] + TETRA).reshape(-1, 3), [(joints[16] + joints[18]) / 2]])
    num_vertices = len(v_template)
    weights = np.zeros((num_vertices, 24))
    weights[np.arange(96), np.repeat(np.arange(24), 4)] = 1.0
    weights[BLENDED, [16, 18]] = 0.5
    regressor = np.zeros((24, num_vertices))
    regressor[np.repeat(np.arange(24), 4), np.arange(96)] = 0.25
    posedirs = rng.normal(0, 0.01, (num_vertices, 3, 207)) if pose_blend else np.zeros((num_vertices, 3, 207))
    return {
        "v_template": v_template,
        "shapedirs": rng.normal(0, 0.01, (num_vertices, 3, num_betas)),
        "posedirs": posedirs,
        "J_regressor": regressor,
        "weights": weights,
        "kintree_table": np.stack([np.array(SMPL24.parents), np.arange(24)]),
        "f": (TETRA_FACES[None] + 4 * np.arange(24)[:, None, None]).reshape(-1, 3).astype(np.uint32),
    }


def write_tiny_smpl_npz(path, **kwargs):
    """Write :func:`tiny_model_arrays` in the smplx ``.npz`` layout and return the path."""
    np.savez(path, **tiny_model_arrays(**kwargs))
    return path
