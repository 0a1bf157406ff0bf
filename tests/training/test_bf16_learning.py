"""QEAN and the streaming dancer learn under ``32-true`` and ``bf16-mixed`` (Lightning's CPU autocast).

Each tiny network overfits one batch with its module's own ``training_step`` and optimiser, the forward in
Lightning's region for the precision and the backward after it, as the Trainer does; the loss must stay
finite at every step and fall to a fraction of its first value. (EMM, text-to-motion, the recognizer, the
head estimator and the bare backbone have their learning tests parametrised the same way in their files.)
"""

from __future__ import annotations

import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.motion.synthetic import synthesize_dance
from skeleton_mamba.tasks.qean.model import QEANConfig
from skeleton_mamba.tasks.qean.module import QEANModule
from skeleton_mamba.tasks.stream.model import motion_to_tokens
from skeleton_mamba.tasks.stream.module import StreamDanceModule
from tests.helpers.precision_cases import TRAINING_PRECISIONS, forward_context

TINY = SkeletonMambaConfig(
    dim=16, depth=1, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
)

pytestmark = pytest.mark.filterwarnings("ignore:You are trying to `self.log\\(\\)`")


def _overfit(module, batch: dict, precision: str, steps: int) -> tuple[float, float]:
    """``steps`` optimiser steps on one batch; returns the first and the mean of the last 10 losses."""
    opt = module.configure_optimizers()
    opt = opt["optimizer"] if isinstance(opt, dict) else opt
    module.train()
    losses = []
    for step in range(steps):
        with forward_context(precision):
            loss = module.training_step(batch, step)
        assert torch.isfinite(loss), (precision, step, losses[-3:])
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    return losses[0], sum(losses[-10:]) / 10


@pytest.mark.parametrize("precision", TRAINING_PRECISIONS)
def test_qean_with_the_mamba_encoder_overfits_a_batch(precision):
    torch.manual_seed(0)
    sizes = dict(
        hidden=32, heads=2, motion_layers=1, audio_layers=1, cross_layers=1, mlp_dim=64, num_periods=2
    )
    network = QEANConfig(**sizes, seed_frames=12, music_frames=24, predict_frames=4, dropout=0.0)
    module = QEANModule(backbone=TINY, network=network, lr=3e-3)
    gen = torch.Generator().manual_seed(0)
    batch = {
        "motion": torch.randn(4, 12, 219, generator=gen),
        "music": torch.randn(4, 24, 35, generator=gen),
        "target": torch.randn(4, 4, 219, generator=gen),
    }
    first, last = _overfit(module, batch, precision, steps=100)
    assert last < 0.5 * first, (precision, first, last)


@pytest.mark.parametrize(
    ("precision", "smoothing_stages"), [(p, 0) for p in TRAINING_PRECISIONS] + [("32-true", 8)]
)
def test_stream_dancer_overfits_two_dances(precision, smoothing_stages):
    """Also through the demo's output low-pass (8 moving averages of decay 0.6, trained through)."""
    torch.manual_seed(0)
    module = StreamDanceModule(backbone=TINY, lr=3e-3, input_noise=0.0, smoothing_stages=smoothing_stages)
    dances = [
        synthesize_dance(bpm, 1.0, fps=30.0, style=s, seed=1) for bpm, s in ((120, "bounce"), (100, "sway"))
    ]
    motion = torch.stack([motion_to_tokens(d) for d in dances])
    batch = {"motion": motion.float(), "music": torch.randn(2, motion.shape[1], 34)}
    first, last = _overfit(module, batch, precision, steps=100)
    assert last < 0.3 * first, (precision, first, last)
