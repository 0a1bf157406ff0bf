"""The MDM-style transformer denoiser (benchmark baseline): masks, the null condition, equal-size width."""

from __future__ import annotations

import torch

from skeleton_mamba.tasks.text2motion.baseline import TransformerDenoiser, width_for_parameters
from skeleton_mamba.tasks.text2motion.model import TextCondition


def test_transformer_denoiser_masks_padding_and_pools_the_caption():
    torch.manual_seed(0)
    model = TransformerDenoiser(text_dim=12, latent=16, layers=2, heads=4).eval()
    x, t = torch.randn(2, 10, 263), torch.tensor([3, 700])
    mask = torch.ones(2, 10, dtype=torch.bool)
    mask[0, 6:] = False
    cond = TextCondition(torch.randn(2, 5, 12), torch.tensor([[1, 1, 1, 0, 0], [1] * 5], dtype=torch.bool))
    with torch.no_grad():
        out = model(x, t, cond, mask)
        changed, tokens = x.clone(), cond.tokens.clone()
        changed[0, 6:], tokens[0, 3:] = 100.0, -50.0  # padded frames, masked caption tokens
        out2 = model(changed, t, TextCondition(tokens, cond.mask), mask)
        unc = model(x, t, None, mask)
        unc2 = model(x, t, TextCondition(cond.tokens, torch.zeros_like(cond.mask)), mask)
    assert out.shape == (2, 10, 263) and out[0, 6:].abs().max() == 0
    torch.testing.assert_close(out2, out, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(unc2, unc, atol=1e-5, rtol=1e-5)
    assert (out - unc).abs().max() > 1e-4


def test_width_for_parameters_is_the_nearest_multiple():
    def count(latent: int) -> int:
        return sum(p.numel() for p in TransformerDenoiser(384, latent, layers=2).parameters())

    target = 1_000_000
    width = width_for_parameters(target, 384, layers=2)
    assert width % 8 == 0
    error = abs(count(width) - target)
    assert error <= abs(count(width - 8) - target) and error <= abs(count(width + 8) - target)
    assert error / target < 0.05


def test_the_baseline_positions_are_mdms_positional_encoding_bit_for_bit():
    """The shared embedding's ``"interleaved"`` order is MDM's ``PositionalEncoding`` (written out here as
    MDM computes it), equal bit for bit, so a transformer baseline's outputs do not change with it."""
    import math

    from skeleton_mamba.tasks.training.diffusion.embedding import sinusoidal_embedding

    for width in (16, 30, 384, 512):
        frames = 200
        position = torch.arange(frames, dtype=torch.float32)[:, None]
        div = torch.exp(torch.arange(0, width, 2, dtype=torch.float32) * (-math.log(10000.0) / width))
        mdm = torch.zeros(frames, width)
        mdm[:, 0::2] = torch.sin(position * div)
        mdm[:, 1::2] = torch.cos(position * div)
        assert torch.equal(sinusoidal_embedding(torch.arange(frames), width, order="interleaved"), mdm)
        # the same frequencies as the [sin, cos] order, channels interleaved
        halves = sinusoidal_embedding(torch.arange(frames), width)
        interleaved = torch.stack((halves[:, : width // 2], halves[:, width // 2 :]), dim=-1).flatten(-2)
        torch.testing.assert_close(interleaved, mdm, atol=1e-5, rtol=0)
