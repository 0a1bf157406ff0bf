"""The one sampling entry point of the generative tasks: :func:`sample`, and its options.

Every task names its sampling options the same way (module arguments, recipes, :class:`SamplingOptions`):
``sampler`` (a name of :data:`~skeleton_mamba.tasks.training.sampler_registry.SAMPLERS`: ``"ddim"``: DDIM over
``sampling_steps`` timesteps with noise ``eta``; ``"ddpm"``: ancestral sampling through all T steps, where
``sampling_steps`` and ``eta`` do not apply; ``"dpmpp"`` / ``"unipc"``: the multistep ODE solvers DPM-Solver++
and UniPC over ``sampling_steps`` timesteps, deterministic, where ``eta`` does not apply, :mod:`~.solvers`)
and ``guidance_weight`` (the classifier-free guidance weight w). Task-specific terms (EgoMusic's head
guidance) are :class:`~.samplers.GuidanceTerm` objects passed as ``guidance``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import torch

from skeleton_mamba.tasks.training.diffusion.gaussian import GaussianDiffusion
from skeleton_mamba.tasks.training.diffusion.samplers import Denoiser
from skeleton_mamba.tasks.training.sampler_registry import get_sampler

__all__ = ["SamplingOptions", "sample"]


@dataclass(frozen=True)
class SamplingOptions:
    """How a task samples (module docstring for the names); checked when made.

    Args:
        sampler: a registered sampler's name (``"ddim"``, ``"ddpm"``, ``"dpmpp"``, ``"unipc"``, ...).
        sampling_steps: timesteps of DDIM and the solvers (DDPM runs all T).
        eta: DDIM noise (0: deterministic; 1: EDGE).
        guidance_weight: classifier-free guidance weight w (1: plain conditional, 0: unconditional).
    """

    sampler: str = "ddim"
    sampling_steps: int = 50
    eta: float = 1.0
    guidance_weight: float = 1.0

    def __post_init__(self) -> None:
        get_sampler(self.sampler)  # an unknown name: a ValueError listing the registered ones
        if isinstance(self.sampling_steps, bool) or not isinstance(self.sampling_steps, int):
            raise ValueError(f"sampling_steps must be an integer, got {self.sampling_steps!r}")
        if self.sampling_steps < 1:
            raise ValueError(f"sampling_steps must be >= 1, got {self.sampling_steps}")
        for name in ("eta", "guidance_weight"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if self.eta < 0:
            raise ValueError(f"eta must be >= 0, got {self.eta}")

    def step_range(self, num_steps: int) -> tuple[int, int] | None:
        """The step counts this sampler takes on a diffusion of T = ``num_steps`` steps: DDIM 1 to T, the
        solvers 2 to T (their last evaluation is x0 at t = 0); None for DDPM, which runs all T."""
        first = get_sampler(self.sampler).first_step
        return None if first is None else (first, num_steps)

    def steps_problem(self, num_steps: int) -> str | None:
        """Why ``sampling_steps`` does not fit a diffusion of ``num_steps`` steps (one phrase), or None."""
        span = self.step_range(num_steps)
        if span is None or span[0] <= self.sampling_steps <= span[1]:
            return None
        low, high = span
        if low > high:
            return f"{self.sampler} needs a model of at least {low} diffusion steps, this one has {num_steps}"
        takes = f"{low} to {high} steps" if low < high else f"{low} step{'s' if low > 1 else ''}"
        takes = f"{takes} on a model of {num_steps} diffusion steps"
        if self.sampling_steps < low:  # a solver's last evaluation is x0 at t = 0, after at least one step
            needs = f"{self.sampler} needs at least {low} sampling steps (the last is x0 at t = 0)"
            return f"{needs}; it takes {takes}"
        return f"{self.sampler} takes {takes}"

    def check_steps(self, num_steps: int) -> None:
        """Refuse a ``sampling_steps`` outside :meth:`step_range` (ValueError naming it and the range)."""
        problem = self.steps_problem(num_steps)
        if problem is not None:
            raise ValueError(f"sampling_steps = {self.sampling_steps}: {problem}")

    @classmethod
    def from_hparams(cls, hparams) -> SamplingOptions:
        """The options stored under their names in a module's hyper-parameters (a mapping)."""
        return cls(**{f.name: hparams[f.name] for f in dataclasses.fields(cls)})

    def override(
        self,
        sampler: str | None = None,
        sampling_steps: int | None = None,
        eta: float | None = None,
        guidance_weight: float | None = None,
    ) -> SamplingOptions:
        """These options with the given ones replaced (``None`` keeps a setting).

        A step count given without a sampler keeps a sampler that takes one and otherwise selects DDIM
        (``sm generate --steps 10`` on a DDPM model samples DDIM with 10 steps); a sampler with a
        :attr:`~.sampler_registry.Sampler.default_steps` chosen without a step count over one without runs
        that count (``sm dance --sampler dpmpp``: :data:`~.solvers.FAST_SOLVER_STEPS`).
        """
        current = get_sampler(self.sampler)
        if sampler is None and sampling_steps is not None and not current.takes_steps:
            sampler = "ddim"
        chosen = get_sampler(sampler) if sampler is not None else None
        if chosen is not None and sampling_steps is None and current.default_steps is None:
            sampling_steps = chosen.default_steps
        given = dict(sampler=sampler, sampling_steps=sampling_steps, eta=eta, guidance_weight=guidance_weight)
        return dataclasses.replace(self, **{k: v for k, v in given.items() if v is not None})

    def describe(self) -> dict:
        """The options as a plain dict, without those the sampler does not use (for reports)."""
        out = dataclasses.asdict(self)
        chosen = get_sampler(self.sampler)
        if not chosen.takes_steps:
            del out["sampling_steps"]
        if not chosen.uses_eta:
            del out["eta"]
        return out


def sample(
    diffusion: GaussianDiffusion,
    denoiser: Denoiser,
    shape: Sequence[int],
    cond: Any = None,
    *,
    sampler: str = "ddim",
    sampling_steps: int = 50,
    eta: float = 1.0,
    **kwargs: Any,
) -> torch.Tensor:
    """x0 samples (B, ...) of ``shape`` from ``denoiser`` by the chosen sampler.

    Args:
        diffusion: the schedule (T = ``diffusion.num_steps``).
        denoiser: ``(x_t, t, cond) -> x0_hat``; a :class:`~.samplers.NullConditioned` one evaluates
            classifier-free guidance in one call.
        shape: the sample shape (B, ...).
        cond: the condition (``None``: unconditional).
        sampler: as :class:`SamplingOptions` (``sample(..., **asdict(options))``).
        sampling_steps: as :class:`SamplingOptions`.
        eta: as :class:`SamplingOptions`.
        **kwargs: the sampler's other options, alike for all (:func:`~.samplers.ddpm_sample`):
            ``guidance_weight``; ``guidance`` terms (e.g. EgoMusic's head guidance); ``clip_x0``;
            ``post_step`` (e.g. window consistency); ``x_T``; ``generator``; ``device``, ``dtype``;
            ``progress``.
    """
    SamplingOptions(sampler, sampling_steps, eta).check_steps(diffusion.num_steps)  # checks them
    run = get_sampler(sampler).run
    return run(diffusion, denoiser, shape, cond, sampling_steps=sampling_steps, eta=eta, **kwargs)
