"""The shared Gaussian diffusion: schedule, posterior, samplers, guidance, window stitching."""

import math

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.training.diffusion import (
    GaussianDiffusion,
    GuidanceTerm,
    NoiseSchedule,
    WindowConsistency,
    ddim_sample,
    ddpm_sample,
    sample_long,
    stitch_windows,
    window_starts,
)
from skeleton_mamba.tasks.training.diffusion.stitching import split_windows


def _closed_form_abar(num_steps: int, s: float = 0.008) -> np.ndarray:
    """alpha_bar_t written directly as prod_{i<=t} f((i+1)/T) / f(i/T) = f((t+1)/T) / f(0) (telescoping)."""
    f = lambda u: math.cos((u + s) / (1 + s) * math.pi / 2) ** 2  # noqa: E731
    return np.array([f((t + 1) / num_steps) / f(0.0) for t in range(num_steps)])


def test_cosine_schedule_matches_closed_form():
    sched = NoiseSchedule.cosine(1000)
    abar = _closed_form_abar(1000)
    # the telescoped product holds wherever beta was not clipped at 0.999 (all but the last step)
    np.testing.assert_allclose(sched.alphas_cumprod[:-1].numpy(), abar[:-1], rtol=1e-9)
    assert sched.betas.max().item() == pytest.approx(0.999)
    assert sched.alphas_cumprod[0].item() == pytest.approx(abar[0])
    np.testing.assert_allclose(sched.alphas_cumprod_prev[1:].numpy(), sched.alphas_cumprod[:-1].numpy())
    assert sched.alphas_cumprod_prev[0].item() == 1.0


def test_q_sample_and_posterior_match_gaussian_bayes():
    diff = GaussianDiffusion(50)
    abar = _closed_form_abar(50)
    gen = torch.Generator().manual_seed(0)
    x0 = torch.randn(4, 3, generator=gen, dtype=torch.float64)
    x_t = torch.randn(4, 3, generator=gen, dtype=torch.float64)
    eps = torch.randn(4, 3, generator=gen, dtype=torch.float64)
    t = torch.tensor([0, 7, 25, 40])
    got = diff.q_sample(x0, t, eps)
    for row, ti in enumerate(t.tolist()):
        a = abar[ti]
        np.testing.assert_allclose(
            got[row].numpy(), math.sqrt(a) * x0[row].numpy() + math.sqrt(1 - a) * eps[row].numpy()
        )
    mean, var, _ = diff.q_posterior(x0, x_t, t)
    for row, ti in enumerate(t.tolist()):
        a_t = abar[ti]
        a_prev = abar[ti - 1] if ti > 0 else 1.0
        alpha = a_t / a_prev
        beta = 1 - alpha
        # product of N(x_t; sqrt(alpha) x_{t-1}, beta) and N(x_{t-1}; sqrt(a_prev) x0, 1 - a_prev)
        if ti == 0:
            np.testing.assert_allclose(mean[row].numpy(), x0[row].numpy(), atol=1e-12)
            assert var[row].abs().max().item() == 0.0
            continue
        precision = alpha / beta + 1 / (1 - a_prev)
        exp_mean = math.sqrt(alpha) * x_t[row].numpy() / beta + math.sqrt(a_prev) * x0[row].numpy() / (
            1 - a_prev
        )
        np.testing.assert_allclose(mean[row].numpy(), exp_mean / precision, rtol=1e-9)
        np.testing.assert_allclose(var[row].numpy(), 1 / precision, rtol=1e-9)
    # eps recovered from x0
    np.testing.assert_allclose(diff.predict_noise_from_x0(got, t, x0).numpy(), eps.numpy(), atol=1e-9)


def _oracle(target):
    return lambda x_t, t, cond: target.to(x_t.dtype).expand_as(x_t)


@pytest.mark.parametrize("sampler", ["ddpm", "ddim"])
def test_oracle_denoiser_ends_at_x0(sampler):
    diff = GaussianDiffusion(30)
    x0 = torch.rand(2, 5, 3) * 2 - 1
    gen = torch.Generator().manual_seed(1)
    if sampler == "ddpm":
        out = ddpm_sample(diff, _oracle(x0), x0.shape, generator=gen)
    else:
        out = ddim_sample(diff, _oracle(x0), x0.shape, sampling_steps=7, eta=1.0, generator=gen)
    torch.testing.assert_close(out, x0, rtol=0, atol=1e-6)


def test_guidance_weight_zero_ignores_condition():
    diff = GaussianDiffusion(20)
    calls = []

    def denoiser(x_t, t, cond):
        calls.append(cond)
        return torch.tanh(x_t) * 0.5 + (0.0 if cond is None else cond)

    out = []
    for cond in (torch.tensor(0.3), torch.tensor(-0.7)):
        gen = torch.Generator().manual_seed(2)
        out += ddim_sample(
            diff, denoiser, (2, 4), cond=cond, sampling_steps=5, guidance_weight=0.0, generator=gen
        )[None]
    torch.testing.assert_close(out[0], out[1])
    assert all(c is None for c in calls)
    # w = 2: unc + 2 (cond - unc) = the unconditional prediction shifted by 2 c
    gen = torch.Generator().manual_seed(2)
    guided = ddim_sample(
        diff, denoiser, (2, 4), cond=torch.tensor(0.25), sampling_steps=1, guidance_weight=2.0, generator=gen
    )
    gen = torch.Generator().manual_seed(2)
    x_T = torch.randn((2, 4), generator=gen)
    torch.testing.assert_close(guided, torch.tanh(x_T) * 0.5 + 0.5)


def test_guidance_term_hooks_are_applied():
    diff = GaussianDiffusion(10)

    class PullToOne(GuidanceTerm):
        def adjust_x0(self, x0, x_t, t):
            return torch.ones_like(x0)

    out = ddpm_sample(
        diff,
        lambda x, t, c: torch.zeros_like(x),
        (3, 2),
        guidance=[PullToOne()],
        generator=torch.Generator().manual_seed(0),
    )
    torch.testing.assert_close(out, torch.ones(3, 2))


def test_windows_and_stitching():
    starts, padded = window_starts(100, 40, 20)
    assert starts == [0, 20, 40, 60] and padded == 100
    seq = torch.arange(30.0)[:, None]
    win = split_windows(seq, 10, 4)
    assert (
        win.shape == (5, 10, 1) and win[1, 0, 0] == 6 and win[-1, -1, 0] == 29
    )  # padded with the last frame
    torch.testing.assert_close(stitch_windows(win, 4, total_frames=30), seq)  # consistent windows round-trip


def test_stitched_sampling_windows_agree_on_overlaps():
    diff = GaussianDiffusion(25)
    overlap = 3

    def denoiser(x_t, t, cond):  # a non-trivial denoiser that ignores the overlap constraint
        return torch.tanh(x_t * 0.7 + cond)

    cond = torch.randn(4, 8, 2)
    windows = ddim_sample(
        diff,
        denoiser,
        (4, 8, 2),
        cond=cond,
        sampling_steps=10,
        post_step=WindowConsistency(overlap, inpaint_last=True),
        generator=torch.Generator().manual_seed(3),
    )
    torch.testing.assert_close(windows[1:, :overlap], windows[:-1, -overlap:], rtol=0, atol=0)
    long = sample_long(
        lambda post, windows: ddpm_sample(
            diff, denoiser, (4, 8, 2), cond=cond, post_step=post, generator=torch.Generator().manual_seed(3)
        ),
        overlap,
        num_windows=4,
    )
    assert long.shape == (8 + 3 * 5, 2)


def _walking_denoiser(velocity: float):
    """An oracle of a model trained on per-window canonical data: every window's x0 is a straight walk
    starting at the origin (channel 0) plus a constant height (channel 1), whatever x_t is."""

    def denoiser(x_t, t, cond):
        k = torch.arange(x_t.shape[1], dtype=x_t.dtype)
        out = torch.empty_like(x_t)
        out[..., 0] = velocity * k
        out[..., 1] = 0.9
        return out

    return denoiser


@pytest.mark.parametrize("sampler", ["ddim", "ddpm"])
def test_relative_channels_continue_across_window_seams(sampler):
    diff = GaussianDiffusion(20)
    windows, width, overlap, v = 4, 10, 4, 0.05
    total = width + (windows - 1) * (width - overlap)
    relative = torch.tensor([1.0, 0.0])  # channel 0 is relative to each window's start, channel 1 absolute

    def run(post, which):
        kwargs = dict(post_step=post, generator=torch.Generator().manual_seed(0))
        shape = (len(range(windows)[which]), width, 2)
        if sampler == "ddim":
            return ddim_sample(diff, _walking_denoiser(v), shape, sampling_steps=5, **kwargs)
        return ddpm_sample(diff, _walking_denoiser(v), shape, **kwargs)

    long = sample_long(run, overlap, relative=relative, num_windows=windows)
    # one continuous walk: x = v * frame over the whole sequence, the height untouched
    expected = torch.stack([v * torch.arange(total, dtype=torch.float32), torch.full((total,), 0.9)], -1)
    torch.testing.assert_close(long, expected, rtol=0, atol=1e-5)
    # without the relative channel every window restarts at the origin: a jump of v * (W - overlap) at seams
    plain = sample_long(run, overlap, num_windows=windows, inpaint_last=True)
    steps = plain[1:, 0] - plain[:-1, 0]
    assert steps.min() < -0.5 * v * (width - overlap)
    faded = sample_long(run, overlap, num_windows=windows)  # cross-faded: no jump, but no walk either
    assert (faded[:, 0] - expected[:, 0]).abs().max() > v * (width - overlap)


def test_the_last_predictions_are_cross_faded_not_overwritten():
    """A denoiser whose every window is the same ramp (0.01 a frame) raised by 0.1 per window, whatever the
    overlap says: a window's copy of the previous tail and its own continuation differ by 0.1 - 0.01 * hop =
    0.04. In-painting after the last step too joins them with a step of 0.05 at each overlap's end; keeping
    the last predictions (the default, as [EDGE]) cross-fades them: no step above the ramp's own 0.01 by
    more than 0.04 / (overlap + 1)."""
    diff, overlap, width, count = GaussianDiffusion(10), 4, 10, 3

    def denoiser(x_t, t, cond):
        k = torch.arange(x_t.shape[1], dtype=x_t.dtype)[None, :, None]
        return 0.01 * k + 0.1 * torch.arange(x_t.shape[0], dtype=x_t.dtype)[:, None, None] + 0 * x_t

    def run(post, which):
        return ddim_sample(diff, denoiser, (count, width, 1), sampling_steps=4, post_step=post,
                           generator=torch.Generator().manual_seed(0))  # fmt: skip

    faded = sample_long(run, overlap, num_windows=count)[:, 0]
    overwritten = sample_long(run, overlap, num_windows=count, inpaint_last=True)[:, 0]
    assert (overwritten[1:] - overwritten[:-1]).abs().max() == pytest.approx(0.05, abs=1e-6)
    assert (faded[1:] - faded[:-1]).abs().max() <= 0.01 + 0.04 / (overlap + 1) + 1e-6
