"""The single-chunk quadratic SSD form for short sequences (reference §2 item 4, §3 "Short sequences").

Y = (Lmask ∘ C Bᵀ)(Δ ⊙ X) + D ⊙ X over the whole sequence as one chunk: no per-chunk states are
formed (an initial state adds exp(ā_l) h₀ C_l and the final state is one P×N matrix per head).
Suited to the joint scan (L = 6), the group scan (L = 40) and the temporal scan (L = 150).
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.chunked import ssd_chunked


def ssd_quadratic(
    x: torch.Tensor,
    dt: torch.Tensor,
    A: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    *,
    D: torch.Tensor | None = None,
    dt_bias: torch.Tensor | None = None,
    dt_softplus: bool = True,
    dt_limit: tuple[float, float] = (0.0, float("inf")),
    initial_state: torch.Tensor | None = None,
    return_final_state: bool = False,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """SSD as one L×L chunk; arguments and results as :func:`ssd_recurrence` (cost O(L²) per head)."""
    return ssd_chunked(
        x, dt, A, B, C, D=D, dt_bias=dt_bias, dt_softplus=dt_softplus, dt_limit=dt_limit,
        initial_state=initial_state, return_final_state=return_final_state, chunk_size=max(1, x.shape[1]),
    )
