"""The SSD under mixed precision: autocast is switched off inside it, so its decays and states stay fp32.

Under ``torch.autocast`` (Lightning's ``bf16-mixed``/``16-mixed``, or a bf16 inference run) the matrix
products of the SSD (C Bᵀ, the masked quadratic form, the chunk states, the one-token state update)
would otherwise be run in bf16: an 8-bit mantissa on the decays exp(cs_i - cs_j) and on a state that
sums hundreds of steps. As ``mamba_ssm`` does, Δ, A, the cumulative sums of Δ·A, the decay factors,
the recurrent states and D stay fp32 ([Mamba-2]): the forms already convert bf16/fp16 inputs to fp32
(:func:`~skeleton_mamba.ssd.discretize.compute_dtype`) and return y in x's dtype; :func:`full_precision`
makes sure autocast does not cast their products back down. Without autocast nothing changes: the
wrapped function runs as it is, bit for bit.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable

import torch

from skeleton_mamba.runtime.precision import PRECISIONS


def autocast_on(t: torch.Tensor) -> bool:
    """Whether autocast is enabled for the device type of ``t`` (``"cpu"``, ``"cuda"``, ...)."""
    return torch.is_autocast_enabled(t.device.type)


def outside_autocast(t: torch.Tensor) -> contextlib.AbstractContextManager:
    """A region without autocast for ``t``'s device type when autocast is on there, else a no-op."""
    if autocast_on(t):
        return torch.autocast(t.device.type, enabled=False)
    return contextlib.nullcontext()


def full_precision(form: Callable) -> Callable:
    """Run ``form(x, ...)`` outside autocast for x's device (the SSD's entry points and backwards).

    The first positional argument that is a tensor decides the device type; a call without autocast
    goes straight to ``form``.
    """

    @functools.wraps(form)
    def wrapped(*args, **kwargs):
        t = next((a for a in args if isinstance(a, torch.Tensor)), None)
        if t is None or not autocast_on(t):
            return form(*args, **kwargs)
        with torch.autocast(t.device.type, enabled=False):
            return form(*args, **kwargs)

    return wrapped


def inference_precision(precision: str, device_type: str = "cpu") -> contextlib.AbstractContextManager:
    """The region an inference runs in: nothing for ``"fp32"``; for ``"bf16"``, ``torch.autocast`` with
    bfloat16 (weights stay fp32; the projections, convolutions and attention run in bf16, the SSD in fp32)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    if precision == "fp32":
        return contextlib.nullcontext()
    return torch.autocast(device_type, dtype=torch.bfloat16)
