"""The head's rotation read from an egocentric video (tasks/egodance/video_rotation.py), and the long-form
heading anchor built on it (sampling.sample_long_dance's ``headings``, stitching's ``anchors``).

The tracker is checked on a video rendered by the EgoAIST++ builder in a procedural room, whose camera path is
known: a dancer that turns a quarter turn and back while swaying, every frame's heading against the truth's.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.egodance.builder.build import BuildConfig, run_build
from skeleton_mamba.tasks.egodance.builder.layout import complete_samples
from skeleton_mamba.tasks.egodance.frames import iter_video_frames
from skeleton_mamba.tasks.egodance.guidance import HeadingGuidance, head_pose_from_camera
from skeleton_mamba.tasks.egodance.heading_frames import head_heading, head_rotation, yaw_matrices
from skeleton_mamba.tasks.egodance.video_rotation import (
    HeadRotationStream,
    align_rotations,
    head_headings,
    intrinsics_for,
)
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from skeleton_mamba.tasks.motion.formats.motion_file import save_motion
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance
from skeleton_mamba.tasks.training.diffusion.stitching import WindowConsistency

FPS = 30.0


@pytest.fixture(scope="module")
def turning_sample(tmp_path_factory):
    """A 6 s sample rendered at 32 px: a sway dance whose root also turns +90 degrees and back."""
    root = tmp_path_factory.mktemp("turning")
    motion = synthesize_dance(120, 6.0, FPS, "sway", 3, swing_side="music")
    t = np.arange(len(motion.poses)) / FPS
    turn = np.radians(90.0) * np.sin(np.pi * t / 6.0) ** 2  # 0 -> 90 degrees at 3 s -> 0
    root_rotation = axis_angle_to_matrix(torch.from_numpy(motion.poses[:, 0]).double())
    motion.poses[:, 0] = matrix_to_axis_angle(yaw_matrices(torch.from_numpy(turn)) @ root_rotation).numpy()
    path = save_motion(root / "motions" / "synthetic_sway_120bpm_s3.npz", motion)
    (root / "motions" / "synthetic_sway_120bpm_s3.wav").write_bytes(b"")
    config = BuildConfig(out=str(root / "ego"), num_rooms=1, fps=FPS, window_s=6.0, width=32, height=32,
                         progress=False, seed=1)  # fmt: skip
    run_build(config, path)
    (sample,) = complete_samples(root / "ego")
    return sample


def _true_headings(sample) -> torch.Tensor:
    camera = np.load(sample / "camera.npz")
    _, head = head_pose_from_camera(camera["positions"], camera["rotations"])
    heading = torch.from_numpy(np.unwrap(head_heading(torch.from_numpy(head)).numpy()))
    return heading - heading[0]


def test_tracked_heading_follows_the_rendered_head_path(turning_sample):
    camera = np.load(turning_sample / "camera.npz")
    stream = HeadRotationStream(torch.from_numpy(camera["K"]).float(), 32)
    for frames in iter_video_frames(turning_sample / "rgb.mp4", 32, None, 16, FPS):
        stream.push(frames)
    tracked = head_headings(stream.finish())
    assert stream.reliable and stream.explained == len(stream.steps)  # every pair a rotation explains
    truth = _true_headings(turning_sample)
    assert len(tracked) == len(truth) == 180
    assert float(torch.rad2deg(truth).max()) > 80  # the path does turn (about +90 degrees and back)
    error = torch.rad2deg(tracked - truth).abs()
    assert float(error.max()) < 6.0, f"heading error up to {float(error.max()):.1f} degrees"
    assert float(error.mean()) < 1.5
    # frame to frame alone drifts more than with keyframes: the keyframes are doing the work
    chain_only = HeadRotationStream(torch.from_numpy(camera["K"]).float(), 32, keyframe=10_000)
    for frames in iter_video_frames(turning_sample / "rgb.mp4", 32, None, 16, FPS):
        chain_only.push(frames)
    assert float(torch.rad2deg(head_headings(chain_only.finish()) - truth).abs().max()) > float(error.max())


def test_align_rotations_recovers_a_known_rotation_of_a_warped_image():
    """A textured image warped by K R K^-1 is aligned back to R (a pure rotation: no parallax)."""
    import kornia

    generator = torch.Generator().manual_seed(0)
    image = torch.nn.functional.interpolate(torch.rand(1, 1, 8, 8, generator=generator), size=(48, 48),
                                            mode="bicubic", align_corners=False)  # fmt: skip
    K = intrinsics_for(48, 90.0)
    angles = torch.tensor([[0.01, -0.05, 0.02]])  # radians: 2.9 degrees of yaw, a little pitch and roll
    R = kornia.geometry.conversions.axis_angle_to_rotation_matrix(angles)
    moved = kornia.geometry.transform.warp_perspective(image, K @ R @ torch.linalg.inv(K), (48, 48))
    found = align_rotations(image, moved, K)
    error = kornia.geometry.conversions.rotation_matrix_to_axis_angle(found @ R.transpose(1, 2)).norm()
    assert float(torch.rad2deg(error)) < 0.3


def test_intrinsics_for_square_frames_of_a_wide_video():
    K = intrinsics_for(64, 90.0, aspect=16 / 9)
    assert float(K[0, 0]) == pytest.approx(32.0) and float(K[1, 1]) == pytest.approx(32.0 * 16 / 9)
    with pytest.raises(ValueError, match="field of view"):
        intrinsics_for(64, 180.0)


def _tokens(headings: torch.Tensor) -> torch.Tensor:
    """Motion tokens (B, T, 24, 10) at rest whose root faces ``headings`` (B, T)."""
    tokens = torch.zeros(*headings.shape, 24, 10, dtype=torch.float64)
    tokens[..., :3] = torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)
    tokens[..., 3:6] = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)
    tokens[..., 0, :6] = torch.cat([yaw_matrices(headings)[..., :, 0], yaw_matrices(headings)[..., :, 1]], -1)
    return tokens


def test_heading_guidance_turns_the_body_to_the_target():
    sampled = torch.tensor([[0.1, 0.5, -0.3, 3.0]], dtype=torch.float64)
    target = torch.tensor([[0.0, 0.2, 0.2, -3.0]], dtype=torch.float64)
    x0 = _tokens(sampled)
    out = HeadingGuidance(target, weight=1.0).adjust_x0(x0, x0, torch.zeros(1))
    assert torch.allclose(head_heading(head_rotation(out)), target, atol=1e-9)  # -3 vs 3: the short way
    half = HeadingGuidance(target, weight=0.5).adjust_x0(x0, x0, torch.zeros(1))
    gap = torch.remainder(target - sampled + torch.pi, 2 * torch.pi) - torch.pi
    assert torch.allclose(head_heading(head_rotation(half)), sampled + 0.5 * gap, atol=1e-9)
    assert torch.equal(out[..., 1:, :], x0[..., 1:, :]) and torch.equal(out[..., 0, 6:], x0[..., 0, 6:])


def test_anchors_replace_the_frames_read_from_the_motion():
    """A known heading between window starts is used as it is; the unknown numbers come from x0_hat."""
    from skeleton_mamba.tasks.egodance.heading_frames import HeadingFrames

    x0 = _tokens(torch.full((3, 8), 0.4, dtype=torch.float64))
    x0[..., 0, 6:9] = torch.tensor([0.3, 0.9, -0.2], dtype=torch.float64)  # the root's position
    anchors = torch.tensor([[float("nan")] * 3, [0.1, float("nan"), float("nan")], [float("nan")] * 3])
    consistency = WindowConsistency(2, frames=HeadingFrames(turn=True), anchors=anchors.double())
    consistency(x0.clone(), x0, 0.5)
    frames = consistency.relative_frames
    assert frames[1, 0] == pytest.approx(0.1) and frames[2, 0] == pytest.approx(0.4)  # anchored / sampled
    assert frames[1, 1:].tolist() == pytest.approx([0.3, -0.2]) and frames[2, 1:].tolist() == pytest.approx(
        [0.3, -0.2]
    )
    with pytest.raises(ValueError, match="anchors are window frames"):
        WindowConsistency(2, anchors=anchors)


def test_frames_no_rotation_explains_are_not_read():
    """Noise frames (no scene turning) align to nothing: the reading is marked unreliable."""
    noise = torch.rand(40, 3, 32, 32, generator=torch.Generator().manual_seed(0))
    stream = HeadRotationStream(intrinsics_for(32), 32)
    stream.push(noise)
    stream.finish()
    assert not stream.reliable and stream.explained == 0
    flat = HeadRotationStream(intrinsics_for(32), 32)  # a covered lens: nothing to align
    flat.push(
        torch.full((40, 3, 32, 32), 0.5) + 0.002 * torch.rand(40, 3, 32, 32, generator=torch.Generator())
    )
    flat.finish()
    assert not flat.reliable


TURN = 0.01  # radians per frame of the turning oracle


def _turning(self, x_t, t, context=None, mask=None):
    """An oracle EMM that, whatever it is given, stands at rest and turns TURN per frame from its window's
    first frame (facing +z there, as a model trained on windows turned to their first heading)."""
    out = torch.zeros_like(x_t)
    out[..., :6] = torch.tensor([1.0, 0.0, 0.0, 0.0, 1.0, 0.0], dtype=x_t.dtype)
    yaw = TURN * torch.arange(x_t.shape[1], dtype=x_t.dtype)
    out[:, :, 0, :6] = torch.cat([yaw_matrices(yaw)[:, :, 0], yaw_matrices(yaw)[:, :, 1]], -1)
    out[:, :, 0, 7] = 0.9
    return out


@pytest.mark.parametrize("anchored", [False, True])
def test_long_dance_holds_the_heading_the_video_shows(tiny_egodance_module, monkeypatch, anchored):
    """A model that keeps turning: without the video's headings its 4 windows turn 3.7 radians in all; with
    them (the video: the head swings 0.3 radians and back) the dance faces as the video says at every
    frame."""
    from skeleton_mamba.tasks.egodance.model import EMM
    from skeleton_mamba.tasks.egodance.sampling import sample_long_dance

    monkeypatch.setattr(EMM, "forward", _turning)
    module = tiny_egodance_module(use_vision=False, head_source="none")
    total = 375  # 4 windows of 150 every 75
    video = 0.3 * torch.sin(torch.arange(total, dtype=torch.float32) / 40.0)
    tokens = sample_long_dance(module.model, module.diffusion, torch.zeros(total, 35), canonical=True,
                               headings=video if anchored else None, sampler="ddim", sampling_steps=2,
                               generator=torch.Generator().manual_seed(0))  # fmt: skip
    heading = torch.from_numpy(np.unwrap(head_heading(head_rotation(tokens.double())).numpy()))
    if anchored:
        assert torch.allclose(heading, video.double(), atol=1e-4)
    else:
        assert float(heading[-1]) == pytest.approx(TURN * (total - 1), abs=1e-3)
