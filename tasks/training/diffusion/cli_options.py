"""The sampling options of the generative commands (``sm dance``, ``sm generate``), spelled alike.

``--sampler ddim|ddpm``, ``--steps N`` (DDIM steps; alone it selects DDIM), ``--eta`` and ``--guidance``
override the checkpoint's :class:`~.sampling.SamplingOptions` (:meth:`~.sampling.SamplingOptions.override`).
"""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.option_types import real_option
from skeleton_mamba.tasks.training.diffusion.sampling import SAMPLERS

__all__ = ["add_sampling_arguments", "sampling_overrides"]


def _steps(text: str) -> int:
    try:
        steps = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of DDIM steps, got {text!r}") from None
    if steps < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1 DDIM step, got {steps}")
    return steps


def add_sampling_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--sampler``, ``--steps``, ``--eta`` and ``--guidance`` (each default: the checkpoint's)."""
    parser.add_argument("--sampler", choices=SAMPLERS, default=None, help="default: the checkpoint's")
    parser.add_argument(
        "--steps", type=_steps, default=None, help="DDIM steps (alone: DDIM; default: the checkpoint's)"
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
        help="classifier-free guidance weight (default: checkpoint's)",
    )


def sampling_overrides(args: argparse.Namespace) -> dict:
    """The keyword arguments of :meth:`~.sampling.SamplingOptions.override` that ``args`` gives."""
    return dict(sampler=args.sampler, sampling_steps=args.steps, eta=args.eta, guidance_weight=args.guidance)
