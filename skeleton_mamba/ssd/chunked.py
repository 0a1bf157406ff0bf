"""Chunked SSD for any length, with initial and final states ([Mamba-2] Listing 1, ``ssd_minimal.py``).

The length is right-padded to a multiple of the chunk size Q with Δ = 0 (so X = Δ·x = 0 and the
decay exp(Δ·A) = 1: padding injects nothing and does not change the state) and cropped afterwards.
Per chunk k, with ā the inclusive cumulative sum of a = Δ·A inside the chunk and T_k its total:

1. s_k = Σ_s exp(T_k - ā_s) Δ_s x_s ⊗ B_s, the state at the end of chunk k from zero;
2. S_{k+1} = exp(T_k) S_k + s_k with S_0 the initial state, a scan over the chunks;
3. Y[l] = Σ_{s≤l} exp(ā_l - ā_s) (C_l·B_s) Δ_s x_s + exp(ā_l) C_l S_k + D x_l: the quadratic form
   inside the chunk plus the entering state's contribution.

All three run in :func:`~skeleton_mamba.ssd.chunk_scan.chunk_scan` (one autograd function: stacked
matrix products, no c×c matrix of decays). A single chunk without states is the quadratic form alone
(:func:`~skeleton_mamba.ssd.intra_chunk.intra_chunk`).
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.chunk_scan import chunk_scan
from skeleton_mamba.ssd.discretize import NO_DT_LIMIT, check_inputs, compute_dtype, padded_inputs, skip_matrix
from skeleton_mamba.ssd.intra_chunk import intra_chunk
from skeleton_mamba.ssd.non_finite import confine_non_finite
from skeleton_mamba.ssd.precision import full_precision


@full_precision
@confine_non_finite
def ssd_chunked(
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
    chunk_size: int = 64,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """SSD by the chunked matrix form; arguments and results as :func:`ssd_recurrence`.

    Args:
        chunk_size: Q, the chunk length (any sequence length works; the last chunk is padded).
    """
    check_inputs(x, dt, A, B, C, D, dt_bias, initial_state)
    if chunk_size < 1:
        raise ValueError(f"ssd_chunked: chunk_size must be >= 1, got {chunk_size}")
    b, L, H, P = x.shape
    G, N = B.shape[2], B.shape[3]
    ct = compute_dtype(x)
    Q = chunk_size
    c = max(1, -(-L // Q))
    xc, delta, Bc, Cc = padded_inputs(x, dt, B, C, dt_bias, dt_softplus, dt_limit, c * Q)
    n = b * c
    xc, delta = xc.reshape(n, Q, H, P), delta.reshape(n, Q, H)
    Bc, Cc = Bc.reshape(n, Q, G, N), Cc.reshape(n, Q, G, N)
    # The log decays enter in float64 whatever the compute dtype: an fp32 cumsum over a chunk
    # (|cs| in the hundreds) puts errors of ~1e-5 on exp(cs_i - cs_j); see intra_chunk.py.
    a = (delta.to(torch.float64) * A.to(torch.float64)).transpose(1, 2)  # (n, H, Q) float64
    D2 = skip_matrix(D, H, P, ct)
    if c > 1 or initial_state is not None or return_final_state:
        h0 = x.new_zeros(b, H, N, P, dtype=ct) if initial_state is None else initial_state.transpose(-1, -2)
        y, final = chunk_scan(xc, delta, a, Bc, Cc, D2, h0)
        final = final.transpose(-1, -2)  # (b, H, P, N)
    else:
        y = intra_chunk(xc, delta, a, Bc, Cc, D2)
    y = y.view(b, c * Q, H, P)[:, :L].to(x.dtype)
    if not return_final_state:
        return y
    return y, final
