"""Chunked SSD for any length, with initial and final states ([Mamba-2] Listing 1, ``ssd_minimal.py``).

The length is right-padded to a multiple of the chunk size Q with Δ = 0 (so X = Δ·x = 0 and the
decay exp(Δ·A) = 1: padding injects nothing and does not change the state) and cropped afterwards.
Per chunk k, with ā the inclusive cumulative sum of a = Δ·A inside the chunk and T_k its total:

1. Y_diag: the quadratic form inside the chunk (:func:`intra_chunk`);
2. s_k = Σ_s exp(T_k - ā_s) Δ_s x_s ⊗ B_s, the state at the end of chunk k from zero;
3. S_{k+1} = exp(T_k) S_k + s_k with S_0 the initial state, a scan over the chunks
   (:class:`StatePassing`: c multiply-adds of states, no c×c matrix of decays);
4. Y_off[l] = exp(ā_l) S_k C_l.

Tensors stay in the (chunk, position, head, channel) layout of the input, so B and C are used
without copies and heads of one B/C group share one matrix product.
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.discretize import check_inputs, compute_dtype, padded_inputs
from skeleton_mamba.ssd.intra_chunk import intra_chunk
from skeleton_mamba.ssd.non_finite import confine_non_finite


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


class StatePassing(torch.autograd.Function):
    """Step 3 as a scan over the chunks, S_{k+1} = d_k S_k + s_k (d_k = exp(T_k)), with its own backward.

    One multiply-add per chunk on the (b, H, P, N) states, in the states' layout: no (c+1)×(c+1) matrix
    of decays (O(c²) work, and at long lengths full of subnormal numbers, slow on a CPU) and no
    layout copies. Backward, with G_k = dL/dS_k: G_c = dL/dS_final, G_k = dL/dS_in[k] + d_k G_{k+1},
    then ds_k = G_{k+1}, dd_k = Σ_{P,N} G_{k+1} ⊙ S_k, dS_0 = G_0.
    Layouts: s (b, c, H, P, N), d (b, c, H), h0 (b, H, P, N) -> S_in (b, c, H, P, N), final (b, H, P, N).
    """

    @staticmethod
    def forward(ctx, s, d, h0):
        b, c = s.shape[:2]
        states = s.new_empty(b, c + 1, *s.shape[2:])
        states[:, 0].copy_(h0)
        for k in range(c):
            torch.addcmul(s[:, k], states[:, k], d[:, k, :, None, None], out=states[:, k + 1])
        ctx.save_for_backward(states, d)
        return states[:, :c], states[:, c]

    @staticmethod
    def backward(ctx, g_in, g_final):
        states, d = ctx.saved_tensors
        c = d.shape[1]
        G = torch.empty_like(states)
        if g_final is None:
            G[:, c].zero_()
        else:
            G[:, c].copy_(g_final)
        for k in range(c - 1, -1, -1):
            if g_in is None:
                torch.mul(G[:, k + 1], d[:, k, :, None, None], out=G[:, k])
            else:
                torch.addcmul(g_in[:, k], G[:, k + 1], d[:, k, :, None, None], out=G[:, k])
        dd = torch.linalg.vecdot(G[:, 1:].flatten(3), states[:, :c].flatten(3))  # (b, c, H)
        return G[:, 1:], dd, G[:, 0]


def pass_states(
    s: torch.Tensor, totals: torch.Tensor, initial_state: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Step 3: the states entering every chunk, S_{k+1} = exp(T_k) S_k + s_k (:class:`StatePassing`).

    Args:
        s: (b, c, H, P, N) chunk states from zero.
        totals: (b, c, H) chunk sums T_k of the log decays (float64).
        initial_state: (b, H, P, N) or ``None`` (zeros).

    Returns:
        (S_in (b, c, H, P, N) the state entering each chunk, final state (b, H, P, N)).
    """
    h0 = s.new_zeros(s.shape[0], *s.shape[2:]) if initial_state is None else initial_state.to(s.dtype)
    return StatePassing.apply(s, torch.exp(totals).to(s.dtype), h0)


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
