"""Step 2 of the chunked SSD: the states entering every chunk, a scan over the chunks ([Mamba-2] SSD).

S_0 = h0, S_{k+1} = d_k S_k + s_k with d_k = exp(T_k) the chunk's total decay: one multiply-add of states
per chunk (O(c), no c×c matrix of decays), forward and backward, for
:class:`~skeleton_mamba.ssd.chunk_scan.ChunkScan`.
"""

from __future__ import annotations

import torch


def decay_factor(log_decay: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """exp(log_decay) in ``dtype``, with results below its smallest normal number set to zero."""
    out = torch.exp(log_decay).to(dtype)
    return out.masked_fill(out < torch.finfo(dtype).tiny, 0.0)


def scan_states(s: torch.Tensor, d: torch.Tensor, h0: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Step 2: S_0 = h0, S_{k+1} = d_k S_k + s_k, one multiply-add per chunk (no c×c matrix of decays).

    Args:
        s: (b, c, H, N, P) the chunks' states from zero.
        d: (b, c, H) the chunks' total decays exp(T_k).
        h0: (b, H, N, P) the initial state.

    Returns:
        S_in (b, c, H, N, P) the state entering every chunk (contiguous), final S_c (b, H, N, P).
    """
    c = s.shape[1]
    S_in = torch.empty_like(s)
    S_in[:, 0].copy_(h0)
    for k in range(c - 1):
        torch.addcmul(s[:, k], S_in[:, k], d[:, k, :, None, None], out=S_in[:, k + 1])
    return S_in, torch.addcmul(s[:, c - 1], S_in[:, c - 1], d[:, c - 1, :, None, None])


def scan_states_backward(
    dS_in: torch.Tensor, d: torch.Tensor, dfinal: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor]:
    """The backward of :func:`scan_states`: G_c = dL/dS_c, G_k = dL/dS_in[k] + d_k G_{k+1}.

    Args:
        dS_in: (b, c, H, N, P) the gradient reaching the entering states.
        d: (b, c, H) the decays of the forward scan.
        dfinal: (b, H, N, P) the gradient of the final state, or ``None`` (zero).

    Returns:
        ds (b, c, H, N, P) with ds_k = G_{k+1} (the gradient of s_k), and dh0 = G_0 (b, H, N, P).
        The gradient of d_k is Σ G_{k+1} ⊙ S_k (left to the caller, who holds S).
    """
    c = dS_in.shape[1]
    ds = torch.empty_like(dS_in)
    if dfinal is None:
        ds[:, c - 1].zero_()
    else:
        ds[:, c - 1].copy_(dfinal)
    for k in range(c - 1, 0, -1):
        torch.addcmul(dS_in[:, k], ds[:, k], d[:, k, :, None, None], out=ds[:, k - 1])
    return ds, torch.addcmul(dS_in[:, 0], ds[:, 0], d[:, 0, :, None, None])
