"""The demos' scores: pose distances, ground contact metrics, the skip parameterisation, and the tables."""

from __future__ import annotations

import math

import pytest
import torch

from skeleton_mamba.tasks.egodance.demo_scores import (
    COLUMNS,
    METRICS,
    format_scores,
    score_held_out,
    target_checks,
)
from skeleton_mamba.tasks.motion.metrics.beat_align import beat_align_over_chance
from skeleton_mamba.tasks.motion.metrics.ground import foot_skating_ratio, ground_penetration
from skeleton_mamba.tasks.motion.metrics.pose_distance import (
    canonical_poses,
    nearest_pose_distance,
    pose_set_distance,
)
from skeleton_mamba.tasks.text2motion.demo_scores import caption_checks, caption_scores
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion
from skeleton_mamba.tasks.training.diffusion.parameterisation import SkipX0


def _yaw(points: torch.Tensor, angle: float) -> torch.Tensor:
    """Rotate (..., 3) y-up points about +y by ``angle`` (right-handed: x -> -z)."""
    c, s = math.cos(angle), math.sin(angle)
    rot = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], dtype=points.dtype)
    return points @ rot.T


def test_canonical_poses_remove_root_position_and_heading():
    torch.manual_seed(0)
    pose = torch.randn(24, 3, dtype=torch.float64)
    pose[1], pose[2] = torch.tensor([0.1, -0.1, 0.3]), torch.tensor([0.4, -0.1, -0.1])
    moved = _yaw(pose, 2.0) + torch.tensor([1.0, 0.5, -3.0], dtype=torch.float64)
    canon = canonical_poses(torch.stack([pose, moved]))
    torch.testing.assert_close(canon[0], canon[1])
    assert canon[0, 0].abs().max() < 1e-12  # root at the origin
    across = canon[0, 2] - canon[0, 1]
    assert abs(across[2].item()) < 1e-12 and across[0] > 0  # hip line along +x
    # distances within the pose are kept
    torch.testing.assert_close(torch.cdist(canon[0], canon[0]), torch.cdist(pose, pose))


def test_nearest_pose_distance_by_hand():
    torch.manual_seed(1)
    reference = torch.randn(5, 24, 3, dtype=torch.float64)
    # frames of the reference, moved and turned: distance 0
    motion = _yaw(reference[[3, 1]], 0.7) + 2.0
    assert nearest_pose_distance(motion, reference).item() == pytest.approx(0.0, abs=1e-12)
    # one joint (not the root or hips) of frame 4 off by 0.24 m: 0.24 / 24 from its nearest pose
    off = reference[4].clone()
    off[10, 1] += 0.24
    far = reference[4] + torch.tensor([0.0, 50.0, 0.0], dtype=torch.float64)
    assert nearest_pose_distance(off[None], torch.stack([reference[4], far])).item() == pytest.approx(0.01)
    assert pose_set_distance(off[None], reference[4:5]).item() == pytest.approx(0.01)


def test_foot_skating_and_ground_penetration_by_hand():
    t = 11
    joints = torch.zeros(t, 24, 3, dtype=torch.float64)
    joints[:, :, 1] = 0.5  # every joint half a metre above the floor
    joints[:, 10, 1] = 0.02  # left toes on the floor, sliding at 0.6 m/s for the first 4 frame pairs
    joints[:5, 10, 0] = torch.arange(5) * 0.6 / 30
    joints[5:, 10, 0] = joints[4, 10, 0]
    joints[:, 11, 1] = 0.2  # right toes in the air, moving fast: no contact, no skating
    joints[:, 11, 2] = torch.arange(t) * 0.1
    assert foot_skating_ratio(joints, fps=30.0).item() == pytest.approx(4 / (2 * (t - 1)))
    assert foot_skating_ratio(joints, fps=30.0, max_speed=0.7).item() == 0.0
    assert ground_penetration(joints).item() == 0.0
    joints[::2, 3, 1] = -0.03  # a joint 3 cm under the floor in 6 of 11 frames
    assert ground_penetration(joints).item() == pytest.approx(0.03 * 6 / t)


def test_skip_parameterisation_recovers_x0_from_v():
    """x0 = sqrt(abar) x_t - sqrt(1 - abar) v with v = sqrt(abar) eps - sqrt(1 - abar) x0 (v-prediction)."""
    torch.manual_seed(2)
    diffusion = GaussianDiffusion(50)
    skip = SkipX0(50)
    x0, eps = torch.randn(3, 7, 5, dtype=torch.float64), torch.randn(3, 7, 5, dtype=torch.float64)
    t = torch.tensor([0, 17, 49])
    abar = diffusion.alphas_cumprod[t].reshape(3, 1, 1)
    x_t = diffusion.q_sample(x0, t, eps)
    v = abar.sqrt() * eps - (1 - abar).sqrt() * x0
    torch.testing.assert_close(skip(x_t, -v, t), x0)
    torch.testing.assert_close(skip(x_t, torch.zeros_like(x_t), t), abar.sqrt() * x_t)


def test_egodance_scores_against_baselines():
    torch.manual_seed(3)
    frames = torch.arange(40, dtype=torch.float64)
    train = []
    for k in range(3):
        clip = torch.randn(24, 3, dtype=torch.float64).expand(40, 24, 3).clone()
        clip[..., 1] = clip[..., 1].abs() + 0.1
        clip[:, 16:, 0] += 0.2 * torch.sin(frames * (0.3 + 0.1 * k))[:, None]  # arms move
        train.append(clip)
    truth = train[1].clone()
    beats = torch.zeros(40)
    beats[[5, 15, 25, 35]] = 1.0
    scores = score_held_out([truth], [truth], [beats], train)
    assert set(scores) == set(COLUMNS) and all(set(v) == set(METRICS) for v in scores.values())
    assert scores["dance"] == scores["ground_truth"] and scores["dance"]["mpjpe_m"] == 0.0
    assert scores["random_clip"]["plausibility_m"] == pytest.approx(0.0, abs=1e-12)  # training clips
    assert scores["mean_pose"]["beat_align"] == 0.0  # a still pose has no kinematic beat
    assert scores["mean_pose"]["beat_margin"] == 0.0  # nor a chance of meeting one
    score, chance = beat_align_over_chance(truth, beats, "bailando", 30.0)
    assert scores["ground_truth"]["beat_margin"] == pytest.approx(score - chance)
    poses = torch.cat(train)
    mean = poses.mean(dim=0)
    expected = (mean - truth).norm(dim=-1).mean().item()
    assert scores["mean_pose"]["mpjpe_m"] == pytest.approx(expected)
    expected_clip = sum((c - truth).norm(dim=-1).mean().item() for c in train) / 3
    assert scores["random_clip"]["mpjpe_m"] == pytest.approx(expected_clip)
    checks = target_checks(scores)
    assert checks["MPJPE below the mean-pose baseline"] and checks["MPJPE below the random-clip baseline"]
    margin = "BeatAlign over chance >= half the ground truth's"
    assert checks[margin]  # the dance is the truth
    off = {
        **scores,
        "dance": {**scores["dance"], "beat_margin": 0.49 * scores["ground_truth"]["beat_margin"]},
    }
    assert scores["ground_truth"]["beat_margin"] > 0 and not target_checks(off)[margin]
    table = format_scores(scores, checks)
    assert "pose plausibility" in table and "reached: plausibility <= 0.08 m" in table


def test_caption_scores_tell_captions_apart():
    torch.manual_seed(4)
    a, b = torch.randn(30, 22, 3, dtype=torch.float64), torch.randn(30, 22, 3, dtype=torch.float64)
    motions = {"a": [a, a.flip(0)], "b": [b, b.roll(5, 0)]}  # same poses, other timing
    scores = caption_scores(motions, torch.cat([a, b]))
    assert scores["plausibility_m"] == pytest.approx(0.0, abs=1e-12)
    assert scores["within_caption_m"] == pytest.approx(0.0, abs=1e-12)
    assert scores["between_captions_m"] == pytest.approx(pose_set_distance(a, b).item())
    assert all(caption_checks(scores).values())
    with pytest.raises(ValueError, match="two captions"):
        caption_scores({"a": [a, a]}, a)
