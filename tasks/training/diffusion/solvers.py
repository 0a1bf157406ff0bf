"""Few-step multistep solvers of the probability-flow ODE, through `diffusers`' schedulers.

``"dpmpp"`` is DPM-Solver++ ([DPM-Solver++], multistep, 2nd order, data prediction) and ``"unipc"`` UniPC
([UniPC], 2nd order, data prediction), the solvers the field samples with in 10-20 steps where [DDIM] needs 50
or more. Our denoisers predict x0 directly, so the schedulers take the model output as the sample
(``prediction_type="sample"``) on the model's own noise schedule (``trained_betas``); classifier-free
guidance, clipping and the guidance terms' ``adjust_x0`` (EgoMusic's head guidance) act on x0_hat before each
solver step exactly as in DDPM / DDIM, and ``post_step`` (in-painting, long-form window consistency) projects
the new sample at its noise level after each step. A solver has no posterior mean: a guidance term that
overrides ``adjust_mean`` is refused.

DPM-Solver++ takes its last step with first-order (Euler) updates (``euler_at_final=True``), not diffusers'
default second-order one: from 15 steps on (below that diffusers lowers the final order anyway, and the two
are the same) the second-order last step left the EgoMusic demo model's dance further from deterministic
DDIM over all steps and more trembling (20 steps: 6.8 against 5.5 mm, energy above 6 Hz 4.6 against 3.9
times the truth's; ``benchmarks/README.md``, "Few-step samplers").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from tqdm.auto import tqdm

from skeleton_mamba.tasks.training.diffusion.gaussian import GaussianDiffusion
from skeleton_mamba.tasks.training.diffusion.samplers import (
    Denoiser,
    GuidanceTerm,
    PostStep,
    initial_noise,
    predict_x0,
)
from skeleton_mamba.tasks.training.sampler_registry import Sampler

__all__ = ["DPMPP", "FAST_SOLVER_STEPS", "SOLVERS", "UNIPC", "make_scheduler", "solver_sample"]

FAST_SOLVER_STEPS = 20
"""The step count a solver (``dpmpp``, ``unipc``) takes when it is chosen without one: on both demo models its
motions are as close to deterministic DDIM over all steps as DDIM 50's, and score as DDIM 50 does (MPJPE,
BeatAlign, amplitude, jitter), in less than half its time (the tables: ``benchmarks/README.md``, "Few-step
samplers")."""

SOLVERS = {
    # name: (diffusers scheduler class, its options)
    "dpmpp": (
        "DPMSolverMultistepScheduler",
        {"algorithm_type": "dpmsolver++", "solver_order": 2, "euler_at_final": True},
    ),
    "unipc": ("UniPCMultistepScheduler", {"solver_order": 2, "predict_x0": True}),
}


def make_scheduler(name: str, diffusion: GaussianDiffusion, solver_steps: int):
    """The `diffusers` scheduler of solver ``name`` on ``diffusion``'s betas, set to ``solver_steps`` steps
    from t = T - 1 down to the noise of t = 0 (``final_sigmas_type="sigma_min"``), their timesteps spread
    evenly over [0, T - 1] (``timestep_spacing="linspace"``, as our DDIM)."""
    import diffusers  # lazy: a slow import (benchmarks/README.md), for the solvers only (not DDPM / DDIM)

    if name not in SOLVERS:
        raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {name!r}")
    if not 1 <= solver_steps < diffusion.num_steps:
        raise ValueError(f"solver steps must be in [1, {diffusion.num_steps - 1}], got {solver_steps}")
    class_name, options = SOLVERS[name]
    scheduler = getattr(diffusers, class_name)(
        num_train_timesteps=diffusion.num_steps,
        trained_betas=diffusion.betas.double().cpu().numpy(),
        prediction_type="sample",
        timestep_spacing="linspace",
        final_sigmas_type="sigma_min",
        **options,
    )
    scheduler.set_timesteps(solver_steps)
    return scheduler


def _refuse_mean_terms(guidance: Sequence[GuidanceTerm]) -> None:
    for term in guidance:
        if type(term).adjust_mean is not GuidanceTerm.adjust_mean:
            raise ValueError(
                f"{type(term).__name__} adjusts the posterior mean, which an ODE solver does not form: "
                "sample it with ddpm or ddim"
            )


@torch.no_grad()
def solver_sample(
    diffusion: GaussianDiffusion,
    denoiser: Denoiser,
    shape: Sequence[int],
    cond: Any = None,
    solver: str = "dpmpp",
    sampling_steps: int = 20,
    guidance_weight: float = 1.0,
    guidance: Sequence[GuidanceTerm] = (),
    clip_x0: float | None = None,
    post_step: PostStep | None = None,
    x_T: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
    device: torch.device | str = "cpu",
    dtype: torch.dtype = torch.float32,
    progress: bool = False,
) -> torch.Tensor:
    """x0 samples (B, ...) by ``solver`` (:data:`SOLVERS`) in ``sampling_steps`` denoiser evaluations
    (each a classifier-free-guided pair when ``guidance_weight`` is not 0 or 1). Deterministic given x_T.

    ``sampling_steps - 1`` solver steps bring x_T down to the noise level of t = 0, and the last evaluation is
    x0_hat there, as DDIM's last step is: ending the solver at zero noise instead takes its final x0_hat from
    the last solver timestep (t = 5 of 100 for 20 steps), whose leftover noise passed through the denoiser
    into the dance (on the EgoMusic demo model at 20 steps, energy above 6 Hz 2.5x DDIM's against 1.3x this
    way, ``benchmarks/README.md``). Other arguments as :func:`~.samplers.ddpm_sample`.
    """
    _refuse_mean_terms(guidance)
    if sampling_steps < 2:
        raise ValueError(
            f"{solver} needs at least 2 sampling steps (the last is x0 at t = 0), got {sampling_steps}"
        )
    scheduler = make_scheduler(solver, diffusion, sampling_steps - 1)
    abar = diffusion.alphas_cumprod
    x = initial_noise(shape, x_T, generator, device, dtype)
    steps = [int(t) for t in scheduler.timesteps]
    levels = [*steps, 0]  # the noise level of x before each solver step, then after the last one

    def signal(level: int | None) -> torch.Tensor:  # (B, 1, ..., 1): sqrt(abar) of a level; None: clean
        value = torch.ones(()) if level is None else abar[level].sqrt()
        return value.to(x).expand(x.shape[0], *[1] * (x.ndim - 1))

    if post_step is not None:
        x = post_step(x, None, signal(levels[0]))
    for k, step in enumerate(tqdm(steps, disable=not progress, desc=solver)):
        t = torch.full((x.shape[0],), step, device=x.device, dtype=torch.long)
        x0 = predict_x0(denoiser, x, t, cond, guidance_weight, clip_x0, guidance)
        x = scheduler.step(x0, step, x).prev_sample.to(dtype)
        if post_step is not None:
            x = post_step(x, x0, signal(levels[k + 1]))
    t = torch.zeros((x.shape[0],), device=x.device, dtype=torch.long)
    x = predict_x0(denoiser, x, t, cond, guidance_weight, clip_x0, guidance)
    if post_step is not None:
        x = post_step(x, x, signal(None))
    return x


def _solver(name: str) -> Sampler:
    """The registry's :class:`~.sampler_registry.Sampler` of solver ``name`` (2 to T steps, no eta)."""

    def run(diffusion, denoiser, shape, cond=None, *, sampling_steps=FAST_SOLVER_STEPS, eta=None, **options):
        return solver_sample(diffusion, denoiser, shape, cond, name, sampling_steps, **options)

    return Sampler(run=run, first_step=2, default_steps=FAST_SOLVER_STEPS)


DPMPP = _solver("dpmpp")
"""``"dpmpp"``: DPM-Solver++ ([DPM-Solver++]) (entry point ``skeleton_mamba.samplers``)."""
UNIPC = _solver("unipc")
"""``"unipc"``: UniPC ([UniPC]) (entry point ``skeleton_mamba.samplers``)."""
