"""The one sampling entry point of the generative tasks: :func:`sample`, and its options.

Every task names its sampling options the same way (module arguments, recipes, :class:`SamplingOptions`):
``sampler`` (``"ddim"``: DDIM over ``sampling_steps`` timesteps with noise ``eta``; ``"ddpm"``: ancestral
sampling through all T steps, where ``sampling_steps`` and ``eta`` do not apply; ``"dpmpp"`` / ``"unipc"``:
the multistep ODE solvers DPM-Solver++ and UniPC over ``sampling_steps`` timesteps, deterministic, where
``eta`` does not apply, :mod:`~.solvers`) and ``guidance_weight``
(the classifier-free guidance weight w). Task-specific terms (EgoMusic's head guidance) are
:class:`~.samplers.GuidanceTerm` objects passed as ``guidance``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import torch

from skeleton_mamba.tasks.motion.commands.cli_options import (
    SAMPLERS,  # torch-free: the commands' --help lists them
)
from skeleton_mamba.tasks.training.diffusion.gaussian import GaussianDiffusion
from skeleton_mamba.tasks.training.diffusion.samplers import Denoiser, ddim_sample, ddpm_sample
from skeleton_mamba.tasks.training.diffusion.solvers import SOLVERS, solver_sample

__all__ = ["FAST_SOLVER_STEPS", "SAMPLERS", "SamplingOptions", "sample"]

FAST_SOLVER_STEPS = 20
"""The step count a solver (``dpmpp``, ``unipc``) takes when it is chosen without one: on both demo models its
motions are as close to deterministic DDIM over all steps as DDIM 50's, and score as DDIM 50 does (MPJPE,
BeatAlign, amplitude, jitter), in less than half its time (the tables: ``benchmarks/README.md``, "Few-step
samplers")."""


@dataclass(frozen=True)
class SamplingOptions:
    """How a task samples (module docstring for the names); checked when made.

    Args:
        sampler: ``"ddim"``, ``"ddpm"``, ``"dpmpp"`` or ``"unipc"``.
        sampling_steps: timesteps of DDIM and the solvers (DDPM runs all T).
        eta: DDIM noise (0: deterministic; 1: EDGE).
        guidance_weight: classifier-free guidance weight w (1: plain conditional, 0: unconditional).
    """

    sampler: str = "ddim"
    sampling_steps: int = 50
    eta: float = 1.0
    guidance_weight: float = 1.0

    def __post_init__(self) -> None:
        if self.sampler not in SAMPLERS:
            raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)}, got {self.sampler!r}")
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
        if self.sampler == "ddpm":
            return None
        return (2 if self.sampler in SOLVERS else 1), num_steps

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
        (``sm generate --steps 10`` on a DDPM model samples DDIM with 10 steps); a solver chosen without a
        step count takes :data:`FAST_SOLVER_STEPS` (``sm dance --sampler dpmpp``).
        """
        if sampler is None and sampling_steps is not None and self.sampler == "ddpm":
            sampler = "ddim"
        if sampler in SOLVERS and sampling_steps is None and self.sampler not in SOLVERS:
            sampling_steps = FAST_SOLVER_STEPS
        given = dict(sampler=sampler, sampling_steps=sampling_steps, eta=eta, guidance_weight=guidance_weight)
        return dataclasses.replace(self, **{k: v for k, v in given.items() if v is not None})

    def describe(self) -> dict:
        """The options as a plain dict, without those the sampler does not use (for reports)."""
        out = dataclasses.asdict(self)
        if self.sampler == "ddpm":
            del out["sampling_steps"]
        if self.sampler != "ddim":
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
    if sampler == "ddpm":
        return ddpm_sample(diffusion, denoiser, shape, cond, **kwargs)
    if sampler in SOLVERS:
        return solver_sample(diffusion, denoiser, shape, cond, sampler, sampling_steps, **kwargs)
    return ddim_sample(diffusion, denoiser, shape, cond, sampling_steps=sampling_steps, eta=eta, **kwargs)
