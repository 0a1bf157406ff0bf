"""SMPL-24 forward kinematics against independent computations (parent walks, scipy rotations)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.body.kinematics import forward_kinematics
from skeleton_mamba.tasks.motion.body.smpl import (
    SMPL_REST_OFFSETS,
    smpl_forward_kinematics,
    smpl_forward_kinematics_axis_angle,
)

# Stanford-TML/EDGE vis.py (the SMPL-24 parents and rest offsets).
REFERENCE_PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]


def test_parents_and_offset_table_match_the_reference():
    assert list(SMPL24.parents) == REFERENCE_PARENTS
    offsets = np.asarray(SMPL_REST_OFFSETS)
    assert offsets.shape == (24, 3)
    np.testing.assert_allclose(offsets[4], [0.04345142, -0.38646945, 0.008037])
    np.testing.assert_allclose(offsets[23], [-0.0887537, -0.00865157, -0.01010708])


def cumulative_rest(root: np.ndarray) -> np.ndarray:
    """Rest joint positions by walking each joint's parent chain up to the root."""
    offsets = np.asarray(SMPL_REST_OFFSETS)
    out = np.zeros((24, 3))
    for j in range(24):
        k, total = j, np.zeros(3)
        while REFERENCE_PARENTS[k] >= 0:
            total += offsets[k]
            k = REFERENCE_PARENTS[k]
        out[j] = root + total
    return out


def test_zero_pose_reproduces_cumulative_rest_offsets():
    root = np.array([0.3, 0.9, -1.2])
    zero_pose = torch.zeros(24, 3, dtype=torch.float64)
    joints = smpl_forward_kinematics_axis_angle(zero_pose, torch.from_numpy(root))
    np.testing.assert_allclose(joints.numpy(), cumulative_rest(root), atol=1e-12)
    # Left ankle by hand: root + lhip + lknee + lankle offsets.
    hand = root + np.array(
        [
            0.05858135 + 0.04345142 - 0.01479032,
            -0.08228004 - 0.38646945 - 0.42687458,
            -0.01766408 + 0.008037 - 0.037428,
        ]
    )
    np.testing.assert_allclose(joints[7].numpy(), hand, atol=1e-12)


def test_one_rotated_joint_by_hand():
    poses = torch.zeros(24, 3, dtype=torch.float64)
    poses[4] = torch.tensor([0.0, 0.0, math.pi / 2])  # left knee, 90 degrees about z
    joints = smpl_forward_kinematics_axis_angle(poses, torch.zeros(3, dtype=torch.float64)).numpy()
    rest = cumulative_rest(np.zeros(3))
    ox, oy, oz = SMPL_REST_OFFSETS[7]
    # Rz(90) maps (x, y, z) to (-y, x, z).
    np.testing.assert_allclose(joints[7], rest[4] + np.array([-oy, ox, oz]), atol=1e-12)
    np.testing.assert_allclose(joints[:7], rest[:7], atol=1e-12)


def test_random_pose_against_scipy_composition():
    rng = np.random.default_rng(0)
    rotvec = rng.normal(scale=0.6, size=(3, 24, 3))
    root = rng.normal(size=(3, 3))
    joints = smpl_forward_kinematics_axis_angle(torch.from_numpy(rotvec), torch.from_numpy(root)).numpy()
    offsets = np.asarray(SMPL_REST_OFFSETS)
    for b in range(3):
        world = [None] * 24
        pos = np.zeros((24, 3))
        for j in range(24):
            local = Rotation.from_rotvec(rotvec[b, j])
            p = REFERENCE_PARENTS[j]
            if p < 0:
                world[j], pos[j] = local, root[b]
            else:
                world[j] = world[p] * local
                pos[j] = pos[p] + world[p].apply(offsets[j])
        np.testing.assert_allclose(joints[b], pos, atol=1e-10)


def test_matrix_and_axis_angle_entry_points_agree_and_batch():
    from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix

    poses = torch.randn(2, 5, 72, generator=torch.Generator().manual_seed(3)) * 0.5
    trans = torch.randn(2, 5, 3)
    a = smpl_forward_kinematics_axis_angle(poses, trans)
    b = smpl_forward_kinematics(axis_angle_to_matrix(poses.reshape(2, 5, 24, 3)), trans)
    assert a.shape == (2, 5, 24, 3)
    assert torch.allclose(a, b)
    with pytest.raises(ValueError, match="SMPL poses"):
        smpl_forward_kinematics_axis_angle(torch.zeros(5, 23, 3), torch.zeros(5, 3))


def test_fk_is_differentiable():
    poses = (torch.randn(4, 24, 3) * 0.3).requires_grad_()
    trans = torch.zeros(4, 3, requires_grad=True)
    joints = smpl_forward_kinematics_axis_angle(poses, trans)
    grad_poses, grad_trans = torch.autograd.grad(joints[:, 20].sum(), [poses, trans])
    assert torch.isfinite(grad_poses).all() and grad_poses[:, 18].abs().sum() > 0
    assert grad_poses[:, 21].abs().sum() == 0  # the right wrist does not move the left wrist
    assert torch.allclose(grad_trans, torch.ones(4, 3))


def test_generic_fk_checks_parent_order():
    with pytest.raises(ValueError, match="not sorted"):
        forward_kinematics(torch.eye(3).expand(2, 3, 3), torch.zeros(3), torch.zeros(2, 3), [1, -1])
    rot = torch.eye(3).expand(2, 3, 3)
    offsets = torch.tensor([[0.0, 1, 0], [0, 0, 0]])
    pos, _ = forward_kinematics(rot, torch.zeros(3), offsets, [1, -1], order=[1, 0])
    assert torch.allclose(pos, torch.tensor([[0.0, 1, 0], [0, 0, 0]]))
