"""The generative commands' sampling options (``sm dance``, ``sm generate``): ``--sampler``, ``--steps``,
``--eta``, ``--guidance``, spelled alike, and the sampling they choose over a checkpoint's.

argparse and the standard library only (``sm CMD --help`` imports no torch): the sampler names come from
:data:`~.sampler_registry.SAMPLERS`' entry points.
"""

from __future__ import annotations

import argparse

from skeleton_mamba.errors import InputError
from skeleton_mamba.pretrained.size_bounds import SIZE_BOUNDS
from skeleton_mamba.tasks.motion.io.option_types import real_option
from skeleton_mamba.tasks.training.sampler_registry import SAMPLERS

__all__ = ["add_sampling_arguments", "checked_sampling", "sampling_overrides"]

MAX_SAMPLING_STEPS = SIZE_BOUNDS["sampling_steps"]


def _steps(text: str) -> int:
    try:
        steps = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of sampling steps, got {text!r}") from None
    if steps < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1 sampling step, got {steps}")
    if steps > MAX_SAMPLING_STEPS:  # no model has more diffusion steps (the loaded model's: checked_sampling)
        limit = f"{MAX_SAMPLING_STEPS:,}"
        raise argparse.ArgumentTypeError(f"expected at most {limit} sampling steps, got {steps}")
    return steps


def add_sampling_arguments(parser: argparse.ArgumentParser) -> None:
    """``--sampler NAME`` (one of :data:`~.sampler_registry.SAMPLERS`), ``--steps N`` (alone on a DDPM model
    it selects DDIM), ``--eta`` and ``--guidance`` of the generative commands (``sm dance``, ``sm generate``),
    each defaulting to the checkpoint's
    :class:`~skeleton_mamba.tasks.training.diffusion.sampling.SamplingOptions`."""
    parser.add_argument("--sampler", choices=SAMPLERS.names(), default=None, help="default: the checkpoint's")
    parser.add_argument(
        "--steps",
        type=_steps,
        default=None,
        help="sampling steps of a sampler that takes a count (alone on a checkpoint whose sampler runs "
        "all steps, such as ddpm: ddim; default: the checkpoint's, or a solver's own count when --sampler "
        "chooses one)",
    )
    parser.add_argument(
        "--eta",
        type=real_option(0.0, 10.0, "a DDIM eta"),
        default=None,
        help="DDIM noise eta (default: the checkpoint's)",
    )
    parser.add_argument(
        "--guidance",
        type=real_option(0.0, 100.0, "a guidance weight"),
        default=None,
        help="classifier-free guidance weight (default: the checkpoint's)",
    )


def sampling_overrides(args: argparse.Namespace) -> dict:
    """The keyword arguments of ``SamplingOptions.override`` that ``args`` gives."""
    return dict(sampler=args.sampler, sampling_steps=args.steps, eta=args.eta, guidance_weight=args.guidance)


def checked_sampling(args: argparse.Namespace, stored, num_steps: int, source: str):
    """The sampling a command runs: the checkpoint's ``stored`` ``SamplingOptions`` with the options of
    ``args`` (:func:`sampling_overrides`), checked against the loaded model's ``num_steps`` diffusion steps
    (``SamplingOptions.steps_problem``) right after the checkpoint loads, before any input is read.

    Raises:
        InputError: naming the option at fault (``--steps``, or ``--sampler`` with its default step count)
            or, when no option set the step count, the checkpoint ``source`` and its ``sampling_steps``.
    """
    sampling = stored.override(**sampling_overrides(args))
    problem = sampling.steps_problem(num_steps)
    if problem is None:
        return sampling
    if args.steps is not None:
        raise InputError(f"--steps {args.steps}: {problem}")
    if args.sampler is not None and sampling.sampling_steps != stored.sampling_steps:
        where = f"--sampler {args.sampler} (its default {sampling.sampling_steps} steps)"
    else:
        where = f"{source}: its sampling_steps {sampling.sampling_steps}"
    raise InputError(f"{where}: {problem}; choose the count with --steps")
