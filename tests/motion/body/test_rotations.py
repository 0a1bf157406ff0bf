"""Rotation conversions, up-axis conversion and frame-rate resampling against hand values and scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from skeleton_mamba.tasks.motion.body import resample
from skeleton_mamba.tasks.motion.body import rotations as rot

RZ90 = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)


def random_axis_angle(n: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    axis = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=torch.float64), dim=-1)
    angle = torch.rand(n, 1, generator=g, dtype=torch.float64) * 3.0  # below pi: unique axis-angle
    return axis * angle


def test_hand_values_90_degrees_about_z():
    aa = torch.tensor([0.0, 0.0, math.pi / 2], dtype=torch.float64)
    assert torch.allclose(rot.axis_angle_to_matrix(aa), RZ90, atol=1e-12)
    s = math.sqrt(0.5)
    assert torch.allclose(rot.axis_angle_to_quaternion(aa), torch.tensor([s, 0, 0, s], dtype=torch.float64))
    assert torch.allclose(rot.quaternion_to_matrix(torch.tensor([s, 0, 0, s], dtype=torch.float64)), RZ90)
    assert torch.allclose(rot.matrix_to_axis_angle(RZ90), aa)
    # 6D = first column then second column of the matrix (Zhou et al.).
    expected_6d = torch.tensor([0, 1, 0, -1, 0, 0], dtype=torch.float64)
    assert torch.allclose(rot.matrix_to_rotation_6d(RZ90), expected_6d)


def test_round_trips_against_scipy():
    aa = random_axis_angle(200)
    matrix = rot.axis_angle_to_matrix(aa)
    expected = Rotation.from_rotvec(aa.numpy()).as_matrix()
    np.testing.assert_allclose(matrix.numpy(), expected, atol=1e-12)
    quat = rot.axis_angle_to_quaternion(aa)
    scipy_xyzw = Rotation.from_rotvec(aa.numpy()).as_quat()
    scipy_wxyz = scipy_xyzw[:, [3, 0, 1, 2]] * np.sign(scipy_xyzw[:, 3:])  # w >= 0 for angles below pi
    np.testing.assert_allclose(quat.numpy(), scipy_wxyz, atol=1e-12)
    assert torch.allclose(rot.matrix_to_axis_angle(matrix), aa, atol=1e-10)
    assert torch.allclose(rot.quaternion_to_axis_angle(quat), aa, atol=1e-10)
    assert torch.allclose(rot.quaternion_to_matrix(rot.matrix_to_quaternion(matrix)), matrix, atol=1e-10)
    assert torch.allclose(rot.rotation_6d_to_matrix(rot.matrix_to_rotation_6d(matrix)), matrix, atol=1e-12)


def test_6d_gram_schmidt_of_a_non_orthonormal_input():
    a1, a2 = torch.tensor([2.0, 0.0, 0.0]), torch.tensor([1.0, 3.0, 0.0])
    matrix = rot.rotation_6d_to_matrix(torch.cat([a1, a2]))
    # b1 = a1/|a1| = x, b2 = the part of a2 orthogonal to x, normalised = y, b3 = x cross y = z.
    assert torch.allclose(matrix, torch.eye(3), atol=1e-7)
    m = rot.rotation_6d_to_matrix(torch.randn(10, 6, generator=torch.Generator().manual_seed(1)))
    assert torch.allclose(m @ m.transpose(-1, -2), torch.eye(3).expand(10, 3, 3), atol=1e-5)
    assert torch.allclose(torch.linalg.det(m), torch.ones(10), atol=1e-5)


def test_batched_leading_shapes():
    aa = random_axis_angle(2 * 3 * 24).reshape(2, 3, 24, 3)
    assert rot.axis_angle_to_matrix(aa).shape == (2, 3, 24, 3, 3)
    assert rot.matrix_to_rotation_6d(rot.axis_angle_to_matrix(aa)).shape == (2, 3, 24, 6)


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX", "ZXZ"])
def test_euler_matches_scipy_intrinsic(order):
    angles = torch.rand(20, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64) * 2 - 1
    expected = Rotation.from_euler(order, angles.numpy()).as_matrix()  # uppercase = intrinsic
    matrix = rot.euler_to_matrix(angles, order)
    np.testing.assert_allclose(matrix.numpy(), expected, atol=1e-12)
    back = rot.matrix_to_euler(matrix, order)
    again = rot.euler_to_matrix(torch.from_numpy(back), order)
    np.testing.assert_allclose(again.numpy(), expected, atol=1e-12)


def test_euler_hand_value_and_bad_order():
    angles = torch.tensor([math.pi / 2, 0.0, 0.0], dtype=torch.float64)
    assert torch.allclose(rot.euler_to_matrix(angles, "ZXY"), RZ90, atol=1e-12)
    with pytest.raises(ValueError, match="Euler order"):
        rot.euler_to_matrix(angles, "ZQY")


def test_resample_keeps_a_constant_rotation_and_picks_every_second_frame():
    constant = rot.axis_angle_to_matrix(random_axis_angle(24)).expand(37, 24, 3, 3).clone()
    for src, dst in ((60, 30), (30, 60), (60, 20), (30, 24)):
        out = resample.resample_rotations(constant, src, dst)
        assert out.shape[0] == math.floor(36 * dst / src) + 1
        assert torch.allclose(out, constant[:1].expand_as(out), atol=1e-9)
    moving = rot.axis_angle_to_matrix(random_axis_angle(300 * 24).reshape(300, 24, 3))
    halved = resample.resample_rotations(moving, 60, 30)
    assert halved.shape[0] == 150
    assert torch.equal(halved, moving[::2])


def test_resample_slerp_midpoint_and_linear_translation():
    aa = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, math.pi / 2]], dtype=torch.float64)
    trans = torch.tensor([[0.0, 1.0, 2.0], [2.0, 1.0, 0.0]], dtype=torch.float64)
    poses, moved = resample.resample_smpl(aa[:, None].expand(2, 24, 3), trans, 30, 60)
    assert poses.shape == (3, 24, 3) and moved.shape == (3, 3)
    # Halfway between 0 and 90 degrees about z is 45 degrees about z.
    assert torch.allclose(poses[1, 0], torch.tensor([0.0, 0.0, math.pi / 4], dtype=torch.float64), atol=1e-9)
    assert torch.allclose(moved[1], torch.tensor([1.0, 1.0, 1.0], dtype=torch.float64))
    assert torch.equal(poses[2], aa[1].expand(24, 3)) and torch.equal(moved[2], trans[1])
