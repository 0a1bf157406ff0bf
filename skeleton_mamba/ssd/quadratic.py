"""The quadratic SSD form for short sequences ([Mamba-2]'s quadratic, attention-like form).

Y = (Lmask ∘ C Bᵀ)(Δ ⊙ X) + D ⊙ X over the whole sequence, with no chunk states. The L×L matrix is
evaluated in blocks of q ≈ ``block_size`` positions (the length is right-padded with Δ = 0 to K
blocks of q, which injects nothing):

- diagonal blocks: the masked quadratic form of :func:`intra_chunk` (mask, per head, q×q);
- below the diagonal, row block I against all earlier positions j < s_I (s_I its first position),
  factorised with an anchor per block so that no per-head mask is formed
  (:mod:`~skeleton_mamba.ssd.below_diagonal`, which has its own backward).

Per head the work is O(L·q) mask entries instead of O(L²) and one (q × s_I)(s_I × R·P) matrix
product per row block and group (R heads per group). Suited to the joint scan (L = 6), the group
scan (L = 40) and the temporal scan (L = 150). With an initial or final state the whole sequence
is one chunk of :func:`ssd_chunked`.
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.below_diagonal import below_diagonal
from skeleton_mamba.ssd.chunked import ssd_chunked
from skeleton_mamba.ssd.discretize import NO_DT_LIMIT, check_inputs, compute_dtype, padded_inputs, skip_matrix
from skeleton_mamba.ssd.intra_chunk import intra_chunk
from skeleton_mamba.ssd.non_finite import confine_non_finite
from skeleton_mamba.ssd.precision import full_precision

# Target block length q, the fastest at L = 150 (4 heads, P = N = 64, fp32, 2 CPU threads).
BLOCK_SIZE = 64


@full_precision
@confine_non_finite
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
    dt_limit: tuple[float, float] = NO_DT_LIMIT,
    initial_state: torch.Tensor | None = None,
    return_final_state: bool = False,
    block_size: int | None = None,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """SSD by the quadratic form; arguments and results as :func:`ssd_recurrence` (cost O(L²) per head).

    Args:
        block_size: target block length q (default ``BLOCK_SIZE``); blocks are balanced, so
            L = 150 with q = 64 gives three blocks of 50.
    """
    if initial_state is not None or return_final_state:
        return ssd_chunked(
            x,
            dt,
            A,
            B,
            C,
            D=D,
            dt_bias=dt_bias,
            dt_softplus=dt_softplus,
            dt_limit=dt_limit,
            initial_state=initial_state,
            return_final_state=return_final_state,
            chunk_size=max(1, x.shape[1]),
        )
    check_inputs(x, dt, A, B, C, D, dt_bias, initial_state)
    block_size = BLOCK_SIZE if block_size is None else block_size
    if block_size < 1:
        raise ValueError(f"ssd_quadratic: block_size must be >= 1, got {block_size}")
    b, L, H, P = x.shape
    G, N = B.shape[2], B.shape[3]
    ct = compute_dtype(x)
    K = max(1, -(-L // block_size))
    q = max(1, -(-L // K))
    xc, delta, Bc, Cc = padded_inputs(x, dt, B, C, dt_bias, dt_softplus, dt_limit, K * q)
    # float64 log decays and their cumulative sums (see intra_chunk.py for why fp32 is not enough)
    a = delta.to(torch.float64) * A.to(torch.float64)  # (b, K·q, H)
    y_off = None
    if K > 1:
        y_off = below_diagonal(xc, delta, a.cumsum(dim=1), Bc, Cc, q).view(b * K, q, H, P)
    D2 = skip_matrix(D, H, P, ct)
    n = b * K
    y = intra_chunk(
        xc.reshape(n, q, H, P),
        delta.reshape(n, q, H),
        a.view(n, q, H).transpose(1, 2),
        Bc.reshape(n, q, G, N),
        Cc.reshape(n, q, G, N),
        D2,
        y_off,
    ).view(b, K * q, H, P)
    return y[:, :L].to(x.dtype)
