"""The few-step solvers (DPM-Solver++, UniPC through `diffusers`) and our DDIM against `diffusers`' DDIM.

On Gaussian data N(m, s^2) the exact x0 predictor is known, and so is the end point of the probability-flow
ODE: the flow keeps each value's standardised position, x0 = m + s (x_T - a m) / sqrt(a^2 s^2 + 1 - a^2) with
a = sqrt(abar_T). The solvers must reach it in few steps, which DDIM does not.
"""

from __future__ import annotations

import pytest
import torch

from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, SamplingOptions, ddim_sample, sample
from skeleton_mamba.tasks.training.diffusion.samplers import GuidanceTerm
from skeleton_mamba.tasks.training.diffusion.solvers import SOLVERS, make_scheduler, solver_sample

diffusers = pytest.importorskip("diffusers", reason="the solvers need diffusers (the [tasks] extra)")

M, S = 0.3, 0.5  # the Gaussian data N(M, S^2)


def _exact_x0(diffusion: GaussianDiffusion):
    """E[x0 | x_t] for data N(M, S^2): M + S^2 a (x_t - a M) / (a^2 S^2 + 1 - a^2), a = sqrt(abar_t)."""

    def denoiser(x_t, t, cond):
        a = diffusion.alphas_cumprod.to(x_t)[t].sqrt().view(-1, *[1] * (x_t.ndim - 1))
        return M + S**2 * a * (x_t - a * M) / (a**2 * S**2 + 1 - a**2)

    return denoiser


def _flow_end(diffusion: GaussianDiffusion, x_T: torch.Tensor) -> torch.Tensor:
    a = diffusion.alphas_cumprod[-1].double().sqrt()
    return M + S * (x_T - a * M) / (a**2 * S**2 + 1 - a**2).sqrt()


@pytest.mark.parametrize("solver", sorted(SOLVERS))
def test_solvers_reach_the_flow_end_point_in_few_steps(solver):
    diffusion = GaussianDiffusion(1000).double()
    x_T = torch.randn(4, 64, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    exact, denoiser = _flow_end(diffusion, x_T), _exact_x0(diffusion)
    kwargs = dict(x_T=x_T, dtype=torch.float64)
    errors = {}
    for steps in (5, 10, 20):
        got = sample(diffusion, denoiser, x_T.shape, sampler=solver, sampling_steps=steps, **kwargs)
        errors[steps] = (got - exact).abs().max().item()
    ddim = {n: (ddim_sample(diffusion, denoiser, x_T.shape, sampling_steps=n, eta=0.0, **kwargs) - exact)
            for n in (10, 20, 1000)}  # fmt: skip
    ddim = {n: e.abs().max().item() for n, e in ddim.items()}
    # measured (max over 256 values of scale ~1): 5 / 10 / 20 steps 0.46 / 0.096 / 0.0052 (DPM-Solver++),
    # 0.41 / 0.075 / 0.0059 (UniPC); DDIM 0.52 / 0.25 / 0.12, and 0.0025 at 1000 steps
    assert errors[20] < errors[10] < errors[5], errors  # converging with the step count
    assert errors[20] < 0.01 and errors[20] < ddim[20] / 10, (errors, ddim)  # 20 steps: 10x closer than DDIM
    assert errors[10] < ddim[10] / 2, (errors, ddim)
    assert ddim[1000] < 0.005, ddim  # DDIM needs ~1000 steps for what the solvers reach in 20


def test_our_ddim_equals_diffusers_ddim_on_the_same_schedule_and_noise():
    """[DDIM] Eq. 12 / 16 as ours and `diffusers`' DDIMScheduler compute it, x0-parameterised, eta 0 and 1.

    Our DDIM steps from each timestep to the next one listed (``ddim_timesteps``: 99, 88, ..., 0 for 10 of
    100), diffusers' back by ``T // num_inference_steps``: on this grid of uniform gap 11 both are the same
    steps once diffusers is told the gap (``num_inference_steps = 100 // 11``)."""
    diffusion = GaussianDiffusion(100).double()

    def denoiser(x_t, t, cond):  # any smooth x0 predictor depending on t
        return torch.tanh(x_t) * (1 + t.double().view(-1, 1) / 100)

    for eta in (0.0, 1.0):
        generator = torch.Generator().manual_seed(1)
        ours = ddim_sample(
            diffusion, denoiser, (3, 8), sampling_steps=10, eta=eta, generator=generator, dtype=torch.float64
        )
        scheduler = diffusers.DDIMScheduler(
            num_train_timesteps=100,
            trained_betas=diffusion.betas.numpy(),
            prediction_type="sample",
            timestep_spacing="linspace",
            clip_sample=False,
            set_alpha_to_one=True,
        )
        # diffusers keeps the schedule in float32, which rounds abar_99 = 2.4e-7 by 40 %: the same schedule
        # in float64, so that the steps are compared and not the rounding
        scheduler.alphas_cumprod = diffusion.alphas_cumprod.clone()
        scheduler.set_timesteps(10)
        timesteps = [int(t) for t in scheduler.timesteps]
        assert timesteps == list(range(99, -1, -11))
        scheduler.num_inference_steps = 100 // 11  # prev_timestep = t - 11: the next listed timestep
        generator = torch.Generator().manual_seed(1)  # the same draws in the same order
        x = torch.randn((3, 8), generator=generator, dtype=torch.float64)
        for k, t in enumerate(timesteps):
            x0 = denoiser(x, torch.full((3,), t), None)
            last = k + 1 == len(timesteps)  # ours draws no noise after the last step (its sigma is 0)
            draw = eta > 0 and not last
            noise = (
                torch.randn((3, 8), generator=generator, dtype=torch.float64) if draw else torch.zeros(3, 8)
            )
            x = scheduler.step(x0, t, x, eta=eta, variance_noise=noise.double()).prev_sample
        torch.testing.assert_close(ours, x, atol=1e-5, rtol=0)


@pytest.mark.parametrize("solver", sorted(SOLVERS))
def test_solvers_take_guidance_and_post_step(solver):
    diffusion = GaussianDiffusion(1000)
    steps = 8
    scheduler = make_scheduler(solver, diffusion, steps - 1)  # the last evaluation is x0 at t = 0
    abar = diffusion.alphas_cumprod.float()
    levels = [int(t) for t in scheduler.timesteps] + [0]  # after the last solver step: t = 0's noise
    expected = [abar[t].sqrt() for t in levels] + [torch.tensor(1.0)]  # then clean
    seen, known = [], torch.full((2, 3), 0.7)

    def inpaint(x, x0, signal):  # the first 3 channels known: held at signal * known (no noise)
        seen.append(signal.flatten()[0])
        assert signal.shape == (2, 1) and (x0 is None) == (len(seen) == 1)
        return torch.cat([signal * known, x[:, 3:]], dim=1)

    class Shift(GuidanceTerm):
        def adjust_x0(self, x0, x_t, t):
            return x0 + 0.1

    x_T = torch.randn(2, 6, generator=torch.Generator().manual_seed(0))
    denoiser = _exact_x0(diffusion)
    plain = solver_sample(diffusion, denoiser, (2, 6), solver=solver, sampling_steps=steps, x_T=x_T)
    shifted = solver_sample(
        diffusion, denoiser, (2, 6), solver=solver, sampling_steps=steps, x_T=x_T, guidance=[Shift()]
    )
    assert (shifted - plain).mean() > 0.05  # adjust_x0 acts on every step's prediction
    got = solver_sample(
        diffusion, denoiser, (2, 6), solver=solver, sampling_steps=steps, x_T=x_T, post_step=inpaint
    )
    torch.testing.assert_close(got[:, :3], known)  # in-painted exactly at the end (signal 1)
    torch.testing.assert_close(torch.stack(seen), torch.stack(expected), atol=1e-6, rtol=0)

    class MeanTerm(GuidanceTerm):
        def adjust_mean(self, mean, variance, x_t, t):
            return mean

    with pytest.raises(ValueError, match="MeanTerm adjusts the posterior mean.*ddpm or ddim"):
        solver_sample(diffusion, denoiser, (2, 6), solver=solver, guidance=[MeanTerm()])


def test_solver_options_and_classifier_free_guidance():
    diffusion = GaussianDiffusion(50)
    options = SamplingOptions("dpmpp", 20, 1.0, 2.0)
    assert options.override(sampling_steps=10) == SamplingOptions("dpmpp", 10, 1.0, 2.0)  # keeps the solver
    ddim = SamplingOptions("ddim", 50, 1.0, 2.0)
    assert ddim.override("unipc") == SamplingOptions("unipc", 20, 1.0, 2.0)  # a solver alone: its 20 steps
    assert ddim.override("unipc", 8) == SamplingOptions("unipc", 8, 1.0, 2.0)
    assert options.describe() == {"sampler": "dpmpp", "sampling_steps": 20, "guidance_weight": 2.0}
    with pytest.raises(ValueError, match=r"solver steps must be in \[1, 49\]"):
        make_scheduler("unipc", diffusion, 50)
    with pytest.raises(ValueError, match="dpmpp needs at least 2 sampling steps"):
        sample(diffusion, lambda x, t, c: x, (1, 2), sampler="dpmpp", sampling_steps=1)

    def denoiser(x_t, t, cond):
        return torch.tanh(x_t) * 0.5 + (0.0 if cond is None else cond)

    x_T = torch.randn(2, 4, generator=torch.Generator().manual_seed(2))
    cond = torch.tensor(0.2)
    run = {w: sample(diffusion, denoiser, (2, 4), cond, sampler="unipc", sampling_steps=6, x_T=x_T,
                     guidance_weight=w) for w in (0.0, 1.0, 3.0)}  # fmt: skip
    assert not torch.allclose(run[1.0], run[0.0]) and not torch.allclose(run[3.0], run[1.0])
    again = sample(
        diffusion, denoiser, (2, 4), cond, sampler="unipc", sampling_steps=6, x_T=x_T, guidance_weight=3.0
    )
    assert torch.equal(again, run[3.0])  # deterministic given x_T
