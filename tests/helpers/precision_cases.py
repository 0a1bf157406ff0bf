"""The training precisions the learning tests run under: Lightning's ``32-true`` and ``bf16-mixed``.

``forward_context(precision)`` is the region Lightning's precision plugin wraps around ``training_step``
for ``--trainer.precision PRECISION`` on a CPU (``bf16-mixed``: ``torch.autocast("cpu", torch.bfloat16)``);
the backward runs after it, as in Lightning.
"""

from __future__ import annotations

import contextlib

from lightning.pytorch.plugins.precision import MixedPrecision

TRAINING_PRECISIONS = ["32-true", "bf16-mixed"]


def forward_context(precision: str) -> contextlib.AbstractContextManager:
    """Lightning's forward region for ``precision`` on a CPU."""
    if precision == "32-true":
        return contextlib.nullcontext()
    return MixedPrecision(precision, "cpu").forward_context()
