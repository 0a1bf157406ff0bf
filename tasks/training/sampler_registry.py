"""The diffusion samplers, by name: :data:`SAMPLERS`, a :class:`~skeleton_mamba.registry.Registry` of
:class:`Sampler` objects.

A sampler is defined where its algorithm is (``DDIM`` and ``DDPM`` in :mod:`.diffusion.samplers`,
DPM-Solver++ and UniPC in :mod:`.diffusion.solvers`) and registered by one line of ``pyproject.toml``::

    [project.entry-points."skeleton_mamba.samplers"]
    ddim = "skeleton_mamba.tasks.training.diffusion.samplers:DDIM"

so that ``sm generate --help`` lists the names without importing torch; a sampler of another
distribution registers the same way, and one defined in a script with ``@SAMPLERS.register("name")``
(``sm`` commands see only the entry points). Everything that takes a sampler name (module arguments,
recipes and their checks, ``--sampler``, :class:`~.diffusion.sampling.SamplingOptions`) reads this
registry, and :func:`~.diffusion.sampling.sample` runs the chosen one. Standard library only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from skeleton_mamba.registry import Registry

__all__ = ["SAMPLERS", "Sampler", "get_sampler"]


@dataclass(frozen=True)
class Sampler:
    """One diffusion sampler.

    Args:
        run: ``(diffusion, denoiser, shape, cond, *, sampling_steps, eta, **options) -> x0 (B, ...)``; the
            options are :func:`~.diffusion.sampling.sample`'s, alike for every sampler.
        first_step: the fewest ``sampling_steps`` it takes (at most T on a model of T diffusion steps);
            ``None``: it runs all T steps and takes no count (DDPM).
        uses_eta: whether ``eta`` (DDIM's noise) changes its result.
        default_steps: the step count it runs when chosen without one over a sampler that has none of its
            own (``sm dance --sampler dpmpp``: 20); ``None``: the stored count is kept.
    """

    run: Callable[..., Any]
    first_step: int | None
    uses_eta: bool = False
    default_steps: int | None = None

    @property
    def takes_steps(self) -> bool:
        """Whether ``sampling_steps`` applies (False: all T steps)."""
        return self.first_step is not None


SAMPLERS: Registry[Sampler] = Registry("sampler", group="skeleton_mamba.samplers")
"""Every sampler by name (the entry points of ``skeleton_mamba.samplers``)."""


def get_sampler(name: str) -> Sampler:
    """The :class:`Sampler` named ``name``.

    Raises:
        UnknownNameError: no sampler has that name (a ``ValueError``; the message lists the names).
        TypeError: the name's entry point is not a :class:`Sampler`.
    """
    sampler = SAMPLERS.get(name)
    if not isinstance(sampler, Sampler):
        raise TypeError(f"sampler {name!r} is registered as {sampler!r}, not a Sampler")
    return sampler
