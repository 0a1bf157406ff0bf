"""The EMM conditioned on the head's turns (``EMMConfig.heading_condition``): the equation, the errors, the
module's plumbing from the camera path, and a tiny model that learns a swing's side from the turns alone."""

from __future__ import annotations

import math
import warnings

import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.egodance.heading_frames import relative_headings, yaw_matrices
from skeleton_mamba.tasks.egodance.losses import emm_losses
from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
from skeleton_mamba.tasks.egodance.representation import encode_motion
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion


def _pitch(angle: torch.Tensor) -> torch.Tensor:
    c, s = angle.cos(), angle.sin()
    zero, one = torch.zeros_like(angle), torch.ones_like(angle)
    rows = [torch.stack([one, zero, zero], -1), torch.stack([zero, c, -s], -1), torch.stack([zero, s, c], -1)]
    return torch.stack(rows, -2)


def test_relative_headings_are_the_yaw_turned_since_frame_0_wrapped():
    """Head rotations yaw(theta_t) @ pitch(p_t): the heading of the forward axis is theta_t whatever the
    pitch, and the turn since frame 0 is wrapped to [-pi, pi) (a head passing +-pi does not jump 2 pi)."""
    theta = torch.tensor([3.0, 3.1, -3.1, -2.9, 2.5, 1.0], dtype=torch.float64)
    pitch = torch.tensor([0.0, 0.3, -0.4, 0.5, -0.2, 0.1], dtype=torch.float64)
    rotation = yaw_matrices(theta) @ _pitch(pitch)
    expected = [math.remainder(float(a - theta[0]), 2 * math.pi) for a in theta]
    torch.testing.assert_close(relative_headings(rotation), torch.tensor(expected, dtype=torch.float64))
    batched = relative_headings(torch.stack([rotation, rotation.flip(0)]))
    assert batched.shape == (2, 6) and float(batched[1, 0]) == 0.0


def _tiny_emm(heading_condition: bool = True, use_vision: bool = False) -> EMM:
    backbone = SkeletonMambaConfig(
        dim=16, depth=1, mlp_dim=32, heads=2, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    resnet = dict(embedding_size=8, hidden_sizes=[8, 16], depths=[1, 1], layer_type="basic")
    network = EMMConfig(
        context_dim=16, use_vision=use_vision, resnet_layers=resnet, freeze_resnet=False, heads=2,
        transformer_ff=32, frame_condition=True, dropout=0.0, heading_condition=heading_condition,
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # random ResNet weights
        return EMM(backbone, network, image_size=32, diffusion_steps=50)


def test_the_turns_are_added_to_every_frame_condition_as_sin_cos():
    """c = fuse(z_a, z_v) + W (sin h'_t, 1 - cos h'_t) / s + b with h' the turns about their window mean and s
    the training turns' spread, computed here from the fusion module's own output; turning the whole window (a
    constant added) changes nothing."""
    torch.manual_seed(0)
    model = _tiny_emm(use_vision=True).eval()
    music, frames = torch.randn(2, 6, 35), torch.rand(2, 6, 3, 32, 32)
    heading = 0.4 * torch.randn(2, 6)
    z_a, z_v = model.encode_modalities(music, frames)
    w, b = model.heading_embedding.weight, model.heading_embedding.bias
    model.heading_scale.fill_(0.25)
    centred = heading - heading.sum(1, keepdim=True) / 6
    sin, versine = centred.sin() / 0.25, (1 - centred.cos()) / 0.25
    expected = model.fusion(z_a, z_v) + sin[..., None] * w[:, 0] + versine[..., None] * w[:, 1] + b
    torch.testing.assert_close(model.encode_condition(music, frames, heading=heading), expected)
    other = model.encode_condition(music, frames, heading=-heading)
    assert (other - expected).abs().amax() > 1e-3  # the turns change the condition
    torch.testing.assert_close(model.encode_condition(music, frames, heading=heading + 0.7), expected)


def test_the_turns_spread_is_that_of_the_training_motion():
    """set_data_statistics: s = std of sin(h) over every frame of the training windows' head turns, h taken
    about each window's mean, read from the motion's own head rotation (a body turning by a known swing)."""
    model = _tiny_emm()
    phase = torch.tensor([0.0, 1.0, 2.5])
    tokens, _ = _swing(phase, 32)
    yaw = 0.3 * torch.cos(2 * math.pi * torch.arange(32) / 16 + phase[:, None])
    root = yaw_matrices(yaw.double()).float()
    tokens[..., 0, :6] = torch.cat([root[..., :, 0], root[..., :, 1]], -1)  # the root turned by yaw
    model.set_data_statistics(tokens)
    centred = yaw - yaw.mean(1, keepdim=True)
    assert float(model.heading_scale) == pytest.approx(float(centred.sin().std()), rel=1e-4)


def test_heading_is_required_by_a_conditioned_emm_and_refused_by_another():
    music = torch.randn(1, 5, 35)
    with pytest.raises(ValueError, match="heading_condition=True.*give heading"):
        _tiny_emm().encode_condition(music)
    with pytest.raises(ValueError, match=r"heading \(1, 4\) does not fit the condition \(1, 5\)"):
        _tiny_emm().encode_condition(music, heading=torch.zeros(1, 4))
    with pytest.raises(ValueError, match="not trained on the head's turns"):
        _tiny_emm(heading_condition=False).encode_condition(music, heading=torch.zeros(1, 5))


def _swing(phase: torch.Tensor, t: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Dances whose left arm swings with ``cos(w t + phase)`` and whose head turns with it (the demo's
    dancers): tokens (B, T, 24, 10) and the head's turns since frame 0 (B, T)."""
    c1 = torch.cos(2 * math.pi * torch.arange(t) / 16 + phase[:, None])
    poses = torch.zeros(len(phase), t, 24, 3)
    poses[..., 16, 2] = 0.8 * c1
    tokens = encode_motion(poses, torch.zeros(len(phase), t, 3))
    return tokens, 0.2 * (c1 - c1[:, :1])


def test_a_tiny_emm_learns_the_side_of_the_swing_from_the_turns_alone():
    """The music says nothing (zeros), the turns say the swing's phase: after training, x0 predicted from
    pure noise swings with the truth (the sine of the arm's angle correlates > 0.8) given the dance's own
    turns, and against it given the turns of the opposite swing (chance would be 0: the side unknown)."""
    torch.manual_seed(0)
    model, diffusion, t = _tiny_emm(), GaussianDiffusion(50), 32
    train, _ = _swing(2 * math.pi * torch.rand(256), t)
    model.set_data_statistics(train)
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3)
    for _ in range(120):
        x0, heading = _swing(2 * math.pi * torch.rand(8), t)
        context = model.encode_condition(torch.zeros(8, t, 35), heading=heading)
        x_t, steps, target = diffusion.training_pair(x0)
        loss = emm_losses(model(x_t, steps, context), target)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()
    phase = torch.linspace(0, 2 * math.pi, 17)[:16]
    truth, heading = _swing(phase, t)
    _, opposite = _swing(phase + math.pi, t)
    x_t = torch.randn_like(truth)
    steps = torch.full((16,), diffusion.num_steps - 1)

    def correlation(turns: torch.Tensor) -> float:
        with torch.no_grad():
            x0 = model(x_t, steps, model.encode_condition(torch.zeros(16, t, 35), heading=turns))
        a, b = x0[..., 16, 1], truth[..., 16, 1]  # sin of the arm's angle about z: the swing itself
        a, b = a - a.mean(1, keepdim=True), b - b.mean(1, keepdim=True)
        return float(torch.nn.functional.cosine_similarity(a, b).mean())

    own, swapped = correlation(heading), correlation(opposite)
    assert own > 0.8 and swapped < -0.5, (own, swapped)


def _batch(t: int = 16, turn: float = 0.3) -> dict:
    gen = torch.Generator().manual_seed(0)
    motion = encode_motion(
        0.2 * torch.randn(2, t, 24, 3, generator=gen), 0.1 * torch.randn(2, t, 3, generator=gen)
    )
    yaw = turn * torch.sin(torch.arange(t) / 3.0)
    return {
        "motion": motion,
        "music": torch.randn(2, t, 35, generator=gen),
        "frames": torch.rand(2, t, 3, 32, 32, generator=gen),
        "head": torch.zeros(2, t, 3),
        "head_rotation": (yaw_matrices(1.0 + yaw) @ _pitch(0.2 * yaw)).float().expand(2, t, 3, 3),
    }


def test_the_module_reads_the_turns_from_the_camera_path(tiny_egodance_module):
    """Training and sampling take the turns since each window's first frame from ``head_rotation``: the loss
    reaches the heading embedding, another camera path gives another dance, and a batch without one is
    refused naming what it lacks."""
    torch.manual_seed(0)
    module = tiny_egodance_module(heading_condition=True, head_source="none")
    batch = _batch()
    torch.testing.assert_close(
        module.condition_heading(module.model, batch), 0.3 * torch.sin(torch.arange(16) / 3.0).expand(2, 16)
    )
    module._losses(batch, torch.Generator().manual_seed(0))["loss"].backward()
    assert module.model.heading_embedding.weight.grad.abs().sum() > 0
    module.eval()
    dance = module.sample(batch)
    other = module.sample({**batch, "head_rotation": _batch(turn=-0.3)["head_rotation"]})
    assert (dance - other).abs().amax() > 1e-3
    with pytest.raises(ValueError, match="needs the camera path's head rotations"):
        module.sample({k: v for k, v in batch.items() if k != "head_rotation"})
