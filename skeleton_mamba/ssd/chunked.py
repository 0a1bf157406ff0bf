"""Chunked SSD for any length, with initial and final states ([Mamba-2] Listing 1, ``ssd_minimal.py``).

The length is right-padded to a multiple of the chunk size Q with Δ = 0 (so X = Δ·x = 0 and the
decay exp(Δ·A) = 1: padding injects nothing and does not change the state) and cropped afterwards.
Per chunk k, with ā the inclusive cumulative sum of a = Δ·A inside the chunk and T_k its total:

1. Y_diag: the quadratic form inside the chunk (:func:`intra_chunk`);
2. s_k = Σ_s exp(T_k - ā_s) Δ_s x_s ⊗ B_s, the state at the end of chunk k from zero;
3. S_{k+1} = exp(T_k) S_k + s_k with S_0 the initial state, evaluated as one product with the
   (c+1)×(c+1) matrix exp(segsum(0, T_0, ..., T_{c-1})) (stable segment sums; one operation
   instead of a Python loop over chunks);
4. Y_off[l] = exp(ā_l) S_k C_l.

Tensors stay in the (chunk, position, head, channel) layout of the input, so B and C are used
without copies and heads of one B/C group share one matrix product.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from einops import rearrange

from skeleton_mamba.ssd.discretize import check_inputs, compute_dtype, padded_inputs
from skeleton_mamba.ssd.intra_chunk import intra_chunk
from skeleton_mamba.ssd.non_finite import confine_non_finite
from skeleton_mamba.ssd.segsum import segsum_stable


def chunk_states(x: torch.Tensor, weight: torch.Tensor, B: torch.Tensor) -> torch.Tensor:
    """Step 2: s_k = Σ_s weight_s x_s ⊗ B_s, the state at the end of each chunk from zero.

    Args:
        x: (n, Q, H, P) inputs of n = b·c chunks.
        weight: (n, Q, H) the factor Δ_s exp(T_k - ā_s).
        B: (n, Q, G, N).

    Returns:
        s (n, H, P, N).
    """
    n, Q, H, P = x.shape
    G, N = B.shape[2], B.shape[3]
    scaled = (x * weight[..., None]).view(n, Q, G, (H // G) * P)
    s = torch.matmul(scaled.transpose(1, 2).transpose(-1, -2), B.transpose(1, 2))  # (n, G, R*P, N)
    return s.reshape(n, H, P, N)


def pass_states(
    s: torch.Tensor, totals: torch.Tensor, initial_state: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Step 3: the states entering every chunk, S_{k+1} = exp(T_k) S_k + s_k.

    Args:
        s: (b, c, H, P, N) chunk states from zero.
        totals: (b, c, H) chunk sums T_k of the log decays (float64).
        initial_state: (b, H, P, N) or ``None`` (zeros).

    Returns:
        (S_in (b, c, H, P, N) the state entering each chunk, final state (b, H, P, N)).
    """
    b, c, H, P, N = s.shape
    h0 = torch.zeros_like(s[:, :1]) if initial_state is None else initial_state.to(s.dtype)[:, None]
    states = rearrange(torch.cat([h0, s], dim=1), "b k h p n -> b h k (p n)")  # (b, H, c+1, P*N)
    log_decay = F.pad(rearrange(totals, "b c h -> b h c"), (1, 0))  # (b, H, c+1)
    # M_kj = exp(T_j + ... + T_{k-1}) for j ≤ k: entry k collects every earlier chunk state.
    out = torch.matmul(torch.exp(segsum_stable(log_decay)).to(states.dtype), states)  # (b, H, c+1, P*N)
    out = rearrange(out, "b h k (p n) -> b k h p n", p=P)
    return out[:, :c], out[:, c]


def state_output(S_in: torch.Tensor, cs: torch.Tensor, C: torch.Tensor) -> torch.Tensor:
    """Step 4: Y_off[k, l] = exp(ā_{k,l}) S_k C_{k,l}.

    Args:
        S_in: (n, H, P, N) states entering each chunk.
        cs: (n, Q, H) inclusive cumulative log decays (float64).
        C: (n, Q, G, N).

    Returns:
        (n, Q, H, P).
    """
    n, H, P, N = S_in.shape
    Q, G = C.shape[1], C.shape[2]
    S = S_in.reshape(n, G, (H // G) * P, N)
    y = torch.matmul(C.transpose(1, 2), S.transpose(-1, -2))  # (n, G, Q, R*P)
    y = y.transpose(1, 2).reshape(n, Q, H, P)
    return y * torch.exp(cs).to(y.dtype)[..., None]


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
    dt_limit: tuple[float, float] = (0.0, float("inf")),
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
    # The log decays are summed in float64 whatever the compute dtype: an fp32 cumsum over a chunk
    # (|cs| in the hundreds) puts errors of ~1e-5 on exp(cs_i - cs_j); see intra_chunk.py.
    delta64 = delta.to(torch.float64)
    cs = (delta64 * A.to(torch.float64)).cumsum(dim=1)  # (n, Q, H) float64
    y_off, final = None, None
    if c > 1 or initial_state is not None or return_final_state:
        total = cs[:, -1:]  # (n, 1, H)
        s = chunk_states(xc, (delta64 * torch.exp(total - cs)).to(ct), Bc).view(b, c, H, P, N)
        S_in, final = pass_states(s, total.view(b, c, H), initial_state)
        y_off = state_output(S_in.reshape(n, H, P, N), cs, Cc)  # (n, Q, H, P)
    D2 = None if D is None else D.to(ct)[:, None].expand(H, P) if D.dim() == 1 else D.to(ct)
    y = intra_chunk(xc, delta, cs.transpose(1, 2), Bc, Cc, D2, y_off).view(b, c * Q, H, P)
    y = y[:, :L].to(x.dtype)
    if not return_final_state:
        return y
    return y, final
