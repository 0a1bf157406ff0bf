"""Segment sums and the causal decay mask exp(segsum) of one chunk (``mamba_ssm/modules/ssd_minimal.py``).

segsum(a)_ij = Σ_{k=j+1}^{i} a_k for i ≥ j and -inf for i < j, so that
Lmask = exp(segsum(a)) is the 1-semiseparable causal decay matrix, and the gradient of the log decays
a through it (:func:`decay_mask_backward`).
"""

from __future__ import annotations

import torch


def decay_mask(cs: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
    """exp(segsum) from the inclusive cumulative sum ``cs`` of the log decays of one chunk.

    Entry [i, j] = exp(cs_i - cs_j) for i ≥ j, 0 above the diagonal. Four passes over the T×T result:
    the difference, a clamp at 0 (so that no entry above the diagonal overflows), exp, and zeroing
    above the diagonal (``tril_``): the same bits as exp of the difference plus a -inf causal bias, without
    exp's slow path for -inf arguments on CPU (``benchmarks/README.md``). The difference of two
    fp32 numbers is correctly rounded, but ``cs`` itself carries the error of its fp32 rounding,
    u·|cs_i| (u = 2^-24), i.e. a relative error of u·|cs_i| on the mask even next to the diagonal.
    :class:`~skeleton_mamba.ssd.intra_chunk.IntraChunk` therefore passes the fp32 rounding ``hi``
    of an fp64 cumulative sum and applies the remainder exp(cs - hi) as row/column factors. With
    a ≤ 0 the cumsum is non-increasing and rounding is monotone, so cs_i - cs_j ≤ 0 for i ≥ j also
    after rounding: the clamp changes no entry on or below the diagonal.
    Not differentiable by autograd (in-place); :class:`IntraChunk` has its own backward.

    Args:
        cs: (..., T) inclusive cumulative sums of a = Δ·A ≤ 0 (any strides).
        out: optional (..., T, T) buffer to write into.

    Returns:
        (..., T, T) decay mask, zero above the diagonal.
    """
    return torch.sub(cs[..., :, None], cs[..., None, :], out=out).clamp_(max=0.0).exp_().tril_()


def decay_mask_backward(M: torch.Tensor) -> torch.Tensor:
    """The gradient of the log decays a through a decay mask, from M = Lmask ∘ ∂L/∂Lmask.

    Lmask_ij = exp(a_{j+1} + ... + a_i) for i ≥ j, so ∂L/∂a_k = Σ_{i ≥ k > j} M_ij: the entries whose
    segment contains k. They are summed as such (a cumulative sum along each row, then a column sum
    strictly below the diagonal), not as Σ_{i≥k} (row sum_i - column sum_i) of M, the form autograd
    through a cumulative sum of a would give: row and column sums both hold the diagonal M_ii, which
    cancels exactly but leaves its rounding, u·|M_ii| per position. Under fast decay the true gradient
    is orders of magnitude below the diagonal, and that rounding was all that reached A and dt.

    Args:
        M: (..., Q, Q), zero above the diagonal; overwritten (used as scratch).

    Returns:
        (..., Q) ∂L/∂a (zero at k = 0: a_0 enters no segment of its own chunk).
    """
    s = M.cumsum_(-1).tril_(-1).sum(-2)  # s_k = Σ_{i>k} Σ_{j≤k} M_ij = ∂L/∂a_{k+1}
    return torch.cat([torch.zeros_like(s[..., :1]), s[..., :-1]], dim=-1)
