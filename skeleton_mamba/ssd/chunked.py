"""Chunked SSD (Listing 1 of Mamba-2, reference §3) for any length, with initial and final states.

The length is right-padded to a multiple of the chunk size Q with Δ = 0 (so X = Δ·x = 0 and the
decay exp(Δ·A) = 1: padding injects nothing and does not change the state) and cropped afterwards.
Per chunk k, with ā the inclusive cumulative sum of a = Δ·A inside the chunk and T_k its total:

1. Y_diag: the quadratic form inside the chunk (:func:`intra_chunk`);
2. s_k = Σ_s exp(T_k - ā_s) X_s ⊗ B_s, the state at the end of chunk k from zero;
3. S_{k+1} = exp(T_k) S_k + s_k with S_0 the initial state (a sequential scan over chunks);
4. Y_off[l] = exp(ā_l) S_k C_l.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from einops import rearrange

from skeleton_mamba.ssd.discretize import check_inputs, compute_dtype, discretize_dt
from skeleton_mamba.ssd.intra_chunk import intra_chunk


def chunk_states(xd: torch.Tensor, cs: torch.Tensor, B: torch.Tensor) -> torch.Tensor:
    """Step 2: states at the end of every chunk from a zero entering state.

    Args:
        xd: (b, c, H, Q, P) discretised inputs.
        cs: (b, c, H, Q) inclusive cumulative log decays within each chunk.
        B: (b, c, G, Q, N).

    Returns:
        s (b, c, H, P, N).
    """
    b, c, H, Q, P = xd.shape
    G = B.shape[2]
    scaled = xd * torch.exp(cs[..., -1:] - cs)[..., None]  # (b, c, H, Q, P)
    scaled = rearrange(scaled, "b c (g r) q p -> b c g (r p) q", g=G)
    s = torch.matmul(scaled, B)  # (b, c, G, R*P, N)
    return s.view(b, c, H, P, -1)


def pass_states(
    s: torch.Tensor, totals: torch.Tensor, initial_state: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Step 3: the states entering every chunk, S_{k+1} = exp(T_k) S_k + s_k.

    Args:
        s: (b, c, H, P, N) chunk states from zero.
        totals: (b, c, H) chunk sums T_k of the log decays.
        initial_state: (b, H, P, N) or ``None`` (zeros).

    Returns:
        (S_in (b, c, H, P, N) the state entering each chunk, final state (b, H, P, N)).
    """
    decay = torch.exp(totals)[..., None, None]  # (b, c, H, 1, 1)
    state = torch.zeros_like(s[:, 0]) if initial_state is None else initial_state.to(s.dtype)
    entering = []
    for k in range(s.shape[1]):
        entering.append(state)
        state = state * decay[:, k] + s[:, k]
    return torch.stack(entering, dim=1), state


def state_output(S_in: torch.Tensor, cs: torch.Tensor, C: torch.Tensor) -> torch.Tensor:
    """Step 4: Y_off[k, l] = exp(ā_{k,l}) S_k C_{k,l}.

    Args:
        S_in: (b, c, H, P, N) states entering each chunk.
        cs: (b, c, H, Q) inclusive cumulative log decays.
        C: (b, c, G, Q, N).

    Returns:
        (b, c, H, Q, P).
    """
    b, c, H, P, N = S_in.shape
    G = C.shape[2]
    S = rearrange(S_in, "b c (g r) p n -> b c g n (r p)", g=G)
    y = torch.matmul(C, S)  # (b, c, G, Q, R*P)
    y = rearrange(y, "b c g q (r p) -> b c (g r) q p", p=P)
    return y * torch.exp(cs)[..., None]


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
    ct = compute_dtype(x)
    Q = chunk_size
    c = max(1, -(-L // Q))
    pad = c * Q - L
    delta = discretize_dt(dt, dt_bias, dt_softplus, dt_limit, ct)  # (b, L, H)
    xc, Bc, Cc = x.to(ct), B.to(ct), C.to(ct)
    if pad:  # Δ = 0 on the padding: no input, no decay
        xc = F.pad(xc, (0, 0, 0, 0, 0, pad))
        delta = F.pad(delta, (0, 0, 0, pad))
        Bc = F.pad(Bc, (0, 0, 0, 0, 0, pad))
        Cc = F.pad(Cc, (0, 0, 0, 0, 0, pad))
    cs = rearrange(delta * A.to(ct), "b (c q) h -> b c h q", q=Q).cumsum(dim=-1)  # (b, c, H, Q)
    y_off, final = None, None
    if c > 1 or initial_state is not None or return_final_state:
        xd = rearrange(xc * delta[..., None], "b (c q) h p -> b c h q p", q=Q)
        Bk = rearrange(Bc, "b (c q) g n -> b c g q n", q=Q)
        Ck = rearrange(Cc, "b (c q) g n -> b c g q n", q=Q)
        S_in, final = pass_states(chunk_states(xd, cs, Bk), cs[..., -1], initial_state)
        y_off = state_output(S_in, cs, Ck).flatten(0, 1)  # (b*c, H, Q, P)
    D2 = None if D is None else D.to(ct)[:, None].expand(H, P) if D.dim() == 1 else D.to(ct)
    y = intra_chunk(
        xc.reshape(b * c, Q, H, P), delta.reshape(b * c, Q, H), cs.flatten(0, 1),
        Bc.reshape(b * c, Q, *Bc.shape[2:]), Cc.reshape(b * c, Q, *Cc.shape[2:]), D2, y_off,
    )
    y = y.view(b, c * Q, H, P)
    y = (y[:, :L] if pad else y).to(x.dtype)
    if not return_final_state:
        return y
    return y, final
