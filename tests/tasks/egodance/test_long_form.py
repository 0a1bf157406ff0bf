"""Long-form sampling of EMM windows in their own canonical frames (tasks/egodance/heading_frames.py,
tasks/training/diffusion/stitching.py): the frames against the data module's canonicalisation, the noisy
transform, and whole sequences rebuilt from oracle windows, in one batch and in several."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.egodance.builder.placement import yaw_matrix
from skeleton_mamba.tasks.egodance.heading_frames import HeadingFrames, head_heading, head_rotation
from skeleton_mamba.tasks.egodance.representation import HEAD_JOINT, ROOT, encode_motion
from skeleton_mamba.tasks.motion.body.kinematics import forward_kinematics
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from skeleton_mamba.tasks.motion.body.smpl import smpl_rest_offsets
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, WindowConsistency, sample_long
from skeleton_mamba.tasks.training.diffusion.samplers import ddim_sample, ddpm_sample
from skeleton_mamba.tasks.training.diffusion.stitching import stitch_windows

SMPL_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)


def _turning_dance(frames: int, seed: int = 0) -> tuple[torch.Tensor, np.ndarray]:
    """SMPL axis-angle poses (T, 24, 3) float64 and root positions (T, 3): a dancer walking on a curve while
    turning (yaw 0 -> 200 degrees), leaning, bending its spine and neck, arms and legs moving."""
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(frames, dtype=torch.float64) / 30.0
    poses = 0.25 * torch.sin(
        2.1 * t[:, None, None] + torch.rand(1, 24, 3, generator=g, dtype=torch.float64) * 6
    )
    yaw = torch.deg2rad(torch.tensor(200.0, dtype=torch.float64)) * t / t[-1]
    lean = 0.2 * torch.sin(1.3 * t)
    orient = axis_angle_to_matrix(torch.stack([torch.zeros_like(t), yaw, torch.zeros_like(t)], -1))
    orient = orient @ axis_angle_to_matrix(torch.stack([lean, torch.zeros_like(t), 0.1 * lean], -1))
    poses[:, 0] = matrix_to_axis_angle(orient)
    root = np.stack([1.5 * np.sin(0.4 * t.numpy()), 0.9 + 0.03 * np.sin(4 * t.numpy()), t.numpy()], -1)
    return poses, root


def _canonical_tokens(poses: torch.Tensor, root: np.ndarray, start: int, length: int) -> torch.Tensor:
    """Motion tokens of frames start..start+length turned and shifted as the data module canonicalises a
    window (:class:`EgoDanceDataset`, canonicalize_init_head): the head joint's world rotation from FK, the
    heading of its forward axis, the root orientation and positions turned by yaw_matrix(-heading), the
    root's first position moved to x = z = 0. Computed in float64 with numpy and the builder's yaw."""
    p, r = poses[start : start + length].clone(), root[start : start + length]
    rotations = axis_angle_to_matrix(p)
    _, world = forward_kinematics(rotations, torch.from_numpy(r), smpl_rest_offsets(), SMPL_PARENTS)
    forward = world[0, HEAD_JOINT, :, 2].numpy()
    turn = yaw_matrix(-float(np.arctan2(forward[0], forward[2])))
    r = r @ turn.T
    p[:, 0] = matrix_to_axis_angle(torch.from_numpy(turn) @ rotations[:, 0])
    r = r - np.array([r[0, 0], 0.0, r[0, 2]])
    return encode_motion(p, torch.from_numpy(r))


def test_head_rotation_is_the_head_joints_world_rotation_from_fk():
    poses, root = _turning_dance(40)
    tokens = encode_motion(poses, torch.from_numpy(root))
    _, world = forward_kinematics(axis_angle_to_matrix(poses), torch.from_numpy(root), smpl_rest_offsets(),
                                  SMPL_PARENTS)  # fmt: skip
    torch.testing.assert_close(head_rotation(tokens), world[:, HEAD_JOINT], rtol=0, atol=1e-10)
    turned = yaw_matrix(0.7) @ np.eye(3)  # a head looking along heading 0.7 rad
    assert head_heading(torch.from_numpy(turned)).item() == pytest.approx(0.7, abs=1e-12)


@pytest.mark.parametrize("start", [0, 17, 45])
def test_to_frame_of_a_windows_first_frame_is_the_data_modules_canonical_window(start):
    poses, root = _turning_dance(90)
    world = encode_motion(poses, torch.from_numpy(root))[None]  # (1, T, 24, 10)
    frames = HeadingFrames(turn=True)
    frame = frames.relative_frame(world[:, start])
    got = frames.to_frame(world[:, start : start + 30], frame)[0]
    expected = _canonical_tokens(poses, root, start, 30)
    # the contacts of a window's last frame count its displacement as 0 (EDGE's rule): not a frame matter
    torch.testing.assert_close(got[:-1], expected[:-1], rtol=0, atol=1e-9)
    torch.testing.assert_close(got[-1, :, :9], expected[-1, :, :9], rtol=0, atol=1e-9)
    # without turning, only the root's horizontal position moves
    plain = HeadingFrames(turn=False)
    moved = plain.to_frame(world[:, start : start + 30], plain.relative_frame(world[:, start]))[0]
    shift = world[0, start, 0, ROOT].clone()
    shift[1] = 0.0
    torch.testing.assert_close(moved[:, 0, ROOT], world[0, start : start + 30, 0, ROOT] - shift)
    torch.testing.assert_close(moved[:, :, :6], world[0, start : start + 30, :, :6], rtol=0, atol=0)


def test_frames_invert_and_compose():
    poses, root = _turning_dance(30, seed=1)
    x = encode_motion(poses, torch.from_numpy(root))[None].expand(2, -1, -1, -1).clone()
    frames = HeadingFrames()
    a = torch.tensor([[0.9, 0.3, -1.2], [-2.5, 0.0, 0.4]], dtype=torch.float64)
    b = torch.tensor([[-0.4, 2.0, 0.5], [1.1, -0.7, 0.2]], dtype=torch.float64)
    torch.testing.assert_close(frames.from_frame(frames.to_frame(x, a), a), x, rtol=0, atol=1e-12)
    nested = frames.from_frame(frames.from_frame(x, b), a)
    torch.testing.assert_close(nested, frames.from_frame(x, frames.compose(a, b)), rtol=0, atol=1e-12)
    torch.testing.assert_close(frames.from_frame(x, frames.identity(2, x)), x, rtol=0, atol=0)


def test_a_noisy_sample_moves_as_its_clean_part_with_orthogonally_turned_noise():
    """``to_frame(s x0 + n, f, s) = s to_frame(x0, f) + L n`` with L the linear part (signal 0), and L keeps
    the noise white: it only turns the root's 3-vectors."""
    poses, root = _turning_dance(20)
    x0 = encode_motion(poses, torch.from_numpy(root))[None]
    noise = torch.randn(x0.shape, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    frames, f, s = HeadingFrames(), torch.tensor([[1.3, 0.8, -0.6]], dtype=torch.float64), 0.37
    moved = frames.to_frame(s * x0 + noise, f, s)
    linear = frames.to_frame(noise, f, 0.0)
    torch.testing.assert_close(moved, s * frames.to_frame(x0, f) + linear, rtol=0, atol=1e-12)
    torch.testing.assert_close(linear.norm(dim=-1), noise.norm(dim=-1), rtol=0, atol=1e-12)
    torch.testing.assert_close(linear[:, :, 0, 6:9].norm(dim=-1), noise[:, :, 0, 6:9].norm(dim=-1))


def _oracle(poses, root, starts, window):
    """A denoiser of canonical windows: whatever x_t, window k's x0 is the dance's frames
    starts[k]..starts[k] + window in their own canonical frame; the condition is the window's index."""
    windows = torch.stack([_canonical_tokens(poses, root, s, window) for s in starts])

    def denoiser(x_t, t, cond):
        return windows[cond.long()].to(x_t.dtype)

    return denoiser


@pytest.mark.parametrize(("sampler", "batch_windows"), [("ddim", None), ("ddim", 2), ("ddpm", 3)])
def test_oracle_windows_rebuild_the_whole_turning_dance(sampler, batch_windows):
    """Seven windows of 30 frames every 20 (overlap 10) of a dance that turns by 200 degrees and walks
    3 m: stitched, in one batch or in batches that continue each other, they are the whole dance in
    window 0's canonical frame. Translation-only frames (a world-yaw model's) cannot join them."""
    window, overlap, count = 30, 10, 7
    total = window + (count - 1) * (window - overlap)
    poses, root = _turning_dance(total)
    starts = [k * (window - overlap) for k in range(count)]
    denoiser = _oracle(poses, root, starts, window)
    diffusion = GaussianDiffusion(20)

    def run(post, which):
        cond = torch.arange(which.start, which.stop)
        shape = (len(cond), window, 24, 10)
        gen = torch.Generator().manual_seed(0)
        if sampler == "ddim":
            return ddim_sample(diffusion, denoiser, shape, cond, 4, eta=0.0, post_step=post, generator=gen,
                               dtype=torch.float64)  # fmt: skip
        return ddpm_sample(
            diffusion, denoiser, shape, cond, post_step=post, generator=gen, dtype=torch.float64
        )

    long = sample_long(run, overlap, total, frames=HeadingFrames(True), num_windows=count,
                       batch_windows=batch_windows)  # fmt: skip
    expected = _canonical_tokens(poses, root, 0, total)
    atol = 1e-9  # both samplers end on x = x0_hat (the DDPM posterior at t = 0 has no x_t term)
    torch.testing.assert_close(long[..., :9], expected[..., :9], rtol=0, atol=atol)
    inner = [f for f in range(total) if f not in {s + window - 1 for s in starts}]  # last frames: contact 1
    torch.testing.assert_close(long[inner, :, 9], expected[inner, :, 9], rtol=0, atol=atol)
    plain = sample_long(run, overlap, total, frames=HeadingFrames(False), num_windows=count)
    assert (plain[:, 0, ROOT] - expected[:, 0, ROOT]).norm(dim=-1).max() > 1.0  # lost at the first turn


def test_overlaps_agree_under_a_denoiser_that_ignores_them():
    """In-painting in turning frames: after sampling, every window's overlap, brought into the global frame,
    is the previous window's tail (the denoiser ignores the constraint; the projection enforces it)."""
    diffusion, overlap = GaussianDiffusion(25), 4
    weights = torch.randn(10, 10, generator=torch.Generator().manual_seed(1)) * 0.3

    def denoiser(x_t, t, cond):
        out = torch.tanh(x_t @ weights + cond[:, None, None, None])
        out[..., 6:9] = out[..., 6:9] + torch.arange(x_t.shape[1])[:, None, None] * 0.05  # a walk
        return out

    consistency = WindowConsistency(overlap, frames=HeadingFrames(True), inpaint_last=True)
    cond = torch.randn(5)
    windows = ddim_sample(diffusion, denoiser, (5, 12, 24, 10), cond, 8, post_step=consistency,
                          generator=torch.Generator().manual_seed(2))  # fmt: skip
    world = consistency.to_global(windows)
    torch.testing.assert_close(world[1:, :overlap], world[:-1, -overlap:], rtol=0, atol=1e-5)
    turns = consistency.relative_frames[1:, 0]
    assert turns.abs().max() > 0.1  # the windows really were turned
    assert not math.isclose(float(windows[1, 0, 0, 6]), float(world[1, 0, 0, 6]), abs_tol=1e-3)


def test_windows_not_inpainted_are_the_windows_sampled_alone_then_joined():
    """``inpaint=False``: the windows are sampled as with no constraint (``join=False`` gives them, drawn with
    the same noise), each one's frame is read from the window before at the last step, and the cross-fade
    joins them; in-painting (the default) changes the windows."""
    diffusion, overlap, window, count = GaussianDiffusion(25), 4, 12, 5
    total = window + (count - 1) * (window - overlap)
    weights = torch.randn(10, 10, generator=torch.Generator().manual_seed(1)) * 0.3

    def denoiser(x_t, t, cond):
        out = torch.tanh(x_t @ weights + cond[:, None, None, None])
        out[..., 6:9] = out[..., 6:9] + torch.arange(x_t.shape[1])[:, None, None] * 0.05  # a walk
        return out

    cond = torch.randn(count)

    def run(post, which):
        return ddim_sample(diffusion, denoiser, (which.stop - which.start, window, 24, 10), cond[which], 6,
                           post_step=post, generator=torch.Generator().manual_seed(which.start))  # fmt: skip

    frames = HeadingFrames(True)
    for batch in (None, 2):
        alone = sample_long(
            run, overlap, total, frames=frames, num_windows=count, batch_windows=batch, join=False
        )
        assert alone.shape == (count, window, 24, 10)
        joined = sample_long(run, overlap, total, frames=frames, num_windows=count, batch_windows=batch,
                             inpaint=False)  # fmt: skip
        if batch is None:
            reference = WindowConsistency(overlap, frames=frames, inpaint=False)
            assert reference(alone, alone, 1.0) is alone  # nothing in-painted, the frames read
            expected = stitch_windows(reference.to_global(alone), overlap, total)
            torch.testing.assert_close(joined, expected, rtol=0, atol=1e-6)
        inpainted = sample_long(run, overlap, total, frames=frames, num_windows=count, batch_windows=batch)
        assert (inpainted - joined).abs().max() > 1e-2


# ------------------------------------------------------------------ scores of a long dance
def test_seam_frames_by_hand():
    from skeleton_mamba.tasks.egodance.long_form_scores import seam_frames

    assert seam_frames([0, 75, 150], 75, 300) == [74, 75, 149, 150, 224, 225]
    assert seam_frames([0], 75, 150) == []
    assert seam_frames([0, 2], 2, 5) == [1, 2, 3]  # frames 0 and 4 lack a speed or acceleration


def test_seam_ratios_see_a_jump_and_not_a_smooth_dance():
    from skeleton_mamba.tasks.egodance.long_form_scores import seam_frames, seam_ratios

    poses, root = _turning_dance(300)
    joints = forward_kinematics(axis_angle_to_matrix(poses), torch.from_numpy(root), smpl_rest_offsets(),
                                SMPL_PARENTS)[0]  # fmt: skip
    seams = seam_frames([0, 75, 150, 225], 75, 300)
    smooth = seam_ratios(joints, seams, 30.0)
    assert all(0.7 < v < 1.3 for v in smooth.values()), smooth
    jumped = joints.clone()
    for s in (75, 150, 225):  # every window restarts 15 cm aside: the root steps at the seam
        jumped[s:, :, 0] += 0.15
    ratios = seam_ratios(jumped, seams, 30.0)
    assert (
        ratios["root_step_ratio"] > 2 and ratios["speed_ratio"] > 1.5 and ratios["acceleration_ratio"] > 1.5
    )


def test_segments_start_canonical_and_drift_measures_a_turned_dance():
    from skeleton_mamba.tasks.egodance.long_form_scores import drift, segments

    poses, root = _turning_dance(120)
    tokens = encode_motion(poses, torch.from_numpy(root))
    cut = segments(tokens, [0, 40, 80], 40, turn=True)
    torch.testing.assert_close(cut[:, 0, 0, ROOT][:, [0, 2]], torch.zeros(3, 2, dtype=cut.dtype))
    torch.testing.assert_close(head_heading(head_rotation(cut[:, 0])), torch.zeros(3, dtype=cut.dtype))
    for k, s in enumerate((0, 40, 80)):  # each segment as the data module would canonicalise it
        torch.testing.assert_close(cut[k, :-1], _canonical_tokens(poses, root, s, 40)[:-1], rtol=0, atol=1e-9)
    frames = HeadingFrames()
    turned = frames.from_frame(
        tokens[None], torch.tensor([[math.radians(30.0), 0.5, 0.0]], dtype=tokens.dtype)
    )[0]
    moved = drift(turned, tokens, 40)
    assert moved["end_heading_error_deg"] == pytest.approx(30.0, abs=1e-6)
    assert moved["end_root_distance_m"] > 0.5 and moved["world_mpjpe_m"] > 0.5
    assert drift(tokens, tokens, 40) == pytest.approx({"world_mpjpe_m": 0, "end_heading_error_deg": 0,
                                                      "end_root_distance_m": 0}, abs=1e-9)  # fmt: skip


def test_the_long_song_is_scored_over_every_window_that_fits():
    """Segments start where windows start, one every hop (each frame in two), the last ending in the song."""
    from skeleton_mamba.tasks.egodance.long_demo import _segment_starts
    from skeleton_mamba.tasks.egodance.long_form import LongForm

    assert _segment_starts(1800, LongForm(150, 75, True)) == list(range(0, 1651, 75))
    assert _segment_starts(400, LongForm(150, 50, True)) == [0, 100, 200]
    assert _segment_starts(100, LongForm(150, 75, True)) == []
