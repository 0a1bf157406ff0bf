"""Ancestral [DDPM] and [DDIM] sampling with classifier-free guidance [CFG] and pluggable guidance terms.

A denoiser is any callable ``(x_t (B, ...), t (B,) long, cond) -> x0_hat (B, ...)``; ``cond=None`` asks
for the unconditional prediction (the task model substitutes its learned null condition). Task code
samples through the one entry point :func:`~skeleton_mamba.tasks.training.diffusion.sampling.sample`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any, Protocol, runtime_checkable

import torch
from tqdm.auto import tqdm

from skeleton_mamba.tasks.training.diffusion.gaussian import GaussianDiffusion, _extract
from skeleton_mamba.tasks.training.sampler_registry import Sampler

__all__ = [
    "DDIM",
    "DDPM",
    "Denoiser",
    "NullConditioned",
    "GuidanceTerm",
    "concat_conditions",
    "guided_x0",
    "ddpm_sample",
    "ddim_sample",
    "ddim_timesteps",
    "initial_noise",
    "predict_x0",
]

Denoiser = Callable[[torch.Tensor, torch.Tensor, Any], torch.Tensor]
PostStep = Callable[[torch.Tensor, torch.Tensor | None, torch.Tensor], torch.Tensor]
"""``post_step(x, x0_hat, signal) -> x``: a projection of the new sample x (B, ...) after every step, given
the prediction x0_hat it came from (None before the first step) and ``signal`` (B, 1, ..., 1) =
sqrt(alpha_bar) of x's noise level (x = signal * x0 + noise; 1 after the last step)."""


@runtime_checkable
class NullConditioned(Protocol):
    """A denoiser that can state its null condition, so classifier-free guidance takes one call.

    ``null_condition(cond)`` is the condition meaning "no condition" for the batch ``cond`` conditions:
    of the same type and batch size (a tensor, or a dataclass of batch-first tensors such as a caption's
    tokens and mask), and ``denoiser(x_t, t, null_condition(cond))`` equals ``denoiser(x_t, t, None)``.
    Both task denoisers implement it (EMM, the text-to-motion ``LengthMaskedDenoiser``).
    """

    def __call__(self, x_t: torch.Tensor, t: torch.Tensor, cond: Any) -> torch.Tensor: ...

    def null_condition(self, cond: Any) -> Any: ...


def concat_conditions(first: Any, second: Any) -> Any:
    """Two conditions joined along the batch: tensors by ``torch.cat``, dataclasses field by field."""
    if torch.is_tensor(first):
        return torch.cat([first, second])
    if dataclasses.is_dataclass(first) and not isinstance(first, type):
        joined = {
            f.name: concat_conditions(getattr(first, f.name), getattr(second, f.name))
            for f in dataclasses.fields(first)
        }
        return dataclasses.replace(first, **joined)
    raise TypeError(f"a condition is a tensor or a dataclass of tensors, got {type(first).__name__}")


class GuidanceTerm:
    """A sampling-time guidance term (e.g. EgoMusic's head guidance G_head).

    Subclasses override one or both hooks; the base class leaves its input unchanged.
    ``adjust_x0`` runs on the (guided, clipped) prediction x0_hat before the posterior is formed;
    ``adjust_mean`` runs on the mean of p(x_{t-1} | x_t) with its variance (B, ...) at hand.
    """

    def adjust_x0(self, x0: torch.Tensor, x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return x0

    def adjust_mean(
        self, mean: torch.Tensor, variance: torch.Tensor, x_t: torch.Tensor, t: torch.Tensor
    ) -> torch.Tensor:
        return mean


def guided_x0(
    denoiser: Denoiser, x_t: torch.Tensor, t: torch.Tensor, cond: Any, guidance_weight: float
) -> torch.Tensor:
    """Classifier-free guidance [CFG] on x0 as [EDGE]: ``unc + w (cond - unc)`` (w = 1 is plain conditional).

    w = 0 returns the unconditional prediction and never evaluates the conditional one. A
    :class:`NullConditioned` denoiser is called once on the doubled batch ``[x_t; x_t]`` with the
    condition ``[cond; null_condition(cond)]``; any other callable twice, with ``cond`` and with ``None``.
    """
    if cond is None or guidance_weight == 0.0:
        return denoiser(x_t, t, None)
    if guidance_weight == 1.0:
        return denoiser(x_t, t, cond)
    if isinstance(denoiser, NullConditioned):
        doubled = concat_conditions(cond, denoiser.null_condition(cond))
        cond_x0, unc_x0 = denoiser(torch.cat([x_t, x_t]), torch.cat([t, t]), doubled).chunk(2)
    else:
        cond_x0 = denoiser(x_t, t, cond)
        unc_x0 = denoiser(x_t, t, None)
    return unc_x0 + guidance_weight * (cond_x0 - unc_x0)


def predict_x0(
    denoiser: Denoiser,
    x: torch.Tensor,
    t: torch.Tensor,
    cond: Any,
    guidance_weight: float,
    clip_x0: float | None,
    guidance: Sequence[GuidanceTerm],
) -> torch.Tensor:
    """x0_hat (B, ...) of every sampler: guided (:func:`guided_x0`), clamped to ``clip_x0``, then adjusted by
    each guidance term's ``adjust_x0``."""
    x0 = guided_x0(denoiser, x, t, cond, guidance_weight)
    if clip_x0 is not None:
        x0 = x0.clamp(-clip_x0, clip_x0)
    for term in guidance:
        x0 = term.adjust_x0(x0, x, t)
    return x0


def initial_noise(shape, x_T, generator, device, dtype) -> torch.Tensor:
    """``x_T`` if given, else standard normal noise of ``shape`` drawn on the CPU with ``generator``."""
    if x_T is not None:
        return x_T
    return torch.randn(shape, generator=generator, device="cpu", dtype=dtype).to(device)


@torch.no_grad()
def ddpm_sample(
    diffusion: GaussianDiffusion,
    denoiser: Denoiser,
    shape: Sequence[int],
    cond: Any = None,
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
    """Ancestral sampling through all T steps: x_{t-1} = mu(x0_hat, x_t) + sigma_t z (z = 0 at t = 0).

    Args:
        diffusion: the schedule.
        denoiser: ``(x_t, t, cond) -> x0_hat``.
        shape: the sample shape (B, ...).
        cond: the condition passed to the denoiser (``None``: unconditional).
        guidance_weight: classifier-free guidance weight w.
        guidance: terms adjusting x0_hat or the posterior mean (:class:`GuidanceTerm`).
        clip_x0: clamp x0_hat to [-clip, clip] ([EDGE]: 1 on normalised data); ``None`` disables.
        post_step: a projection ``(x, x0_hat, signal) -> x`` applied after every step (:data:`PostStep`;
            e.g. window consistency).
        x_T: the starting noise (default: drawn with ``generator``).
        generator: a CPU generator for reproducible noise.
        device: where to sample.
        dtype: the dtype to sample in.
        progress: show a tqdm bar.

    Returns:
        x0 samples (B, ...).
    """
    x = initial_noise(shape, x_T, generator, device, dtype)
    if post_step is not None:
        last = torch.full((x.shape[0],), diffusion.num_steps - 1, device=x.device, dtype=torch.long)
        x = post_step(x, None, _extract(diffusion.alphas_cumprod, last, x).sqrt())
    for i in tqdm(
        reversed(range(diffusion.num_steps)), total=diffusion.num_steps, disable=not progress, desc="DDPM"
    ):
        t = torch.full((x.shape[0],), i, device=x.device, dtype=torch.long)
        x0 = predict_x0(denoiser, x, t, cond, guidance_weight, clip_x0, guidance)
        mean, var, log_var = diffusion.q_posterior(x0, x, t)
        for term in guidance:
            mean = term.adjust_mean(mean, var, x, t)
        if i > 0:
            z = torch.randn(x.shape, generator=generator, device="cpu", dtype=x.dtype).to(x.device)
            x = mean + (0.5 * log_var).exp() * z
        else:
            x = mean
        if post_step is not None:
            x = post_step(x, x0, _extract(diffusion.alphas_cumprod_prev, t, x).sqrt())
    return x


def ddim_timesteps(num_steps: int, sampling_steps: int) -> list[int]:
    """The descending timesteps of a DDIM run: ``sampling_steps`` values evenly spread over [0, T-1]."""
    if not 1 <= sampling_steps <= num_steps:
        raise ValueError(f"sampling_steps must be in [1, {num_steps}], got {sampling_steps}")
    seq = torch.linspace(0, num_steps - 1, sampling_steps).round().long().unique().tolist()
    return sorted(seq, reverse=True)


@torch.no_grad()
def ddim_sample(
    diffusion: GaussianDiffusion,
    denoiser: Denoiser,
    shape: Sequence[int],
    cond: Any = None,
    sampling_steps: int = 50,
    eta: float = 1.0,
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
    """[DDIM] over ``sampling_steps`` timesteps; [EDGE] uses 50 steps with eta = 1.

    ``x_prev = sqrt(abar_prev) x0_hat + sqrt(1 - abar_prev - sigma^2) eps_hat + sigma z`` ([DDIM] Eq. 12)
    with ``sigma = eta sqrt((1 - abar_prev) / (1 - abar_t)) sqrt(1 - abar_t / abar_prev)`` (Eq. 16) and
    abar_prev = 1 after the last step, so the final x equals the last x0_hat. Other arguments as
    :func:`ddpm_sample`.
    """
    x = initial_noise(shape, x_T, generator, device, dtype)
    steps = ddim_timesteps(diffusion.num_steps, sampling_steps)
    if post_step is not None:
        first = torch.full((x.shape[0],), steps[0], device=x.device, dtype=torch.long)
        x = post_step(x, None, _extract(diffusion.alphas_cumprod, first, x).sqrt())
    for k, i in enumerate(tqdm(steps, disable=not progress, desc="DDIM")):
        t = torch.full((x.shape[0],), i, device=x.device, dtype=torch.long)
        x0 = predict_x0(denoiser, x, t, cond, guidance_weight, clip_x0, guidance)
        eps = diffusion.predict_noise_from_x0(x, t, x0)
        abar = _extract(diffusion.alphas_cumprod, t, x)
        if k + 1 < len(steps):
            abar_prev = _extract(diffusion.alphas_cumprod, torch.full_like(t, steps[k + 1]), x)
        else:
            abar_prev = torch.ones_like(abar)
        sigma = eta * ((1 - abar_prev) / (1 - abar) * (1 - abar / abar_prev)).clamp_min(0).sqrt()
        mean = abar_prev.sqrt() * x0 + (1 - abar_prev - sigma**2).clamp_min(0).sqrt() * eps
        for term in guidance:
            mean = term.adjust_mean(mean, (sigma**2).expand_as(x), x, t)
        if k + 1 < len(steps) and eta > 0:
            z = torch.randn(x.shape, generator=generator, device="cpu", dtype=x.dtype).to(x.device)
            x = mean + sigma * z
        else:
            x = mean
        if post_step is not None:
            x = post_step(x, x0, abar_prev.sqrt())
    return x


def _ddpm(diffusion, denoiser, shape, cond=None, *, sampling_steps=None, eta=None, **options) -> torch.Tensor:
    """:func:`ddpm_sample` with the registry's arguments (all T steps: no count, no eta)."""
    return ddpm_sample(diffusion, denoiser, shape, cond, **options)


def _ddim(diffusion, denoiser, shape, cond=None, *, sampling_steps=50, eta=1.0, **options) -> torch.Tensor:
    """:func:`ddim_sample` with the registry's arguments."""
    return ddim_sample(diffusion, denoiser, shape, cond, sampling_steps=sampling_steps, eta=eta, **options)


DDPM = Sampler(run=_ddpm, first_step=None)
"""``"ddpm"``: ancestral [DDPM] sampling through all T steps (entry point ``skeleton_mamba.samplers``)."""
DDIM = Sampler(run=_ddim, first_step=1, uses_eta=True)
"""``"ddim"``: [DDIM] over 1 to T steps with noise eta (entry point ``skeleton_mamba.samplers``)."""
