"""Segment sums and the causal decay mask exp(segsum) of one chunk (reference §2, §3 step 1).

segsum(a)_ij = Σ_{k=j+1}^{i} a_k for i ≥ j and -inf for i < j, so that
Lmask = exp(segsum(a)) is the 1-semiseparable causal decay matrix.
"""

from __future__ import annotations

import torch


def segsum_stable(a: torch.Tensor) -> torch.Tensor:
    """The stable O(T²) segment sum (as ``ssd_minimal.segsum``): every entry sums only its own terms.

    Args:
        a: (..., T) log decays.

    Returns:
        (..., T, T) with entry [i, j] = a_{j+1} + ... + a_i for i ≥ j, -inf above the diagonal.
    """
    T = a.shape[-1]
    x = a[..., None].expand(*a.shape, T)  # x[..., i, j] = a_i
    strict = torch.ones(T, T, dtype=torch.bool, device=a.device).tril(-1)
    x = x.masked_fill(~strict, 0.0).cumsum(dim=-2)
    return x.masked_fill(~strict.logical_or(torch.eye(T, dtype=torch.bool, device=a.device)), -torch.inf)


def decay_mask(cs: torch.Tensor) -> torch.Tensor:
    """exp(segsum) from the inclusive cumulative sum ``cs`` of the log decays of one chunk.

    Entry [i, j] = exp(cs_i - cs_j) for i ≥ j, 0 above the diagonal (exp(-inf)); three passes over
    the T×T result (difference, causal -inf bias, exp) and no -inf - (-inf). The difference of two
    cumulative sums carries an absolute error of about u·|cs_i| (u = 2^-24 in fp32), i.e. a relative
    error of u·|cs_i| on the mask: below 1e-5 while |cs_i| < 160, which the tests check against
    :func:`segsum_stable` in float64. With a ≤ 0 the fp32 cumsum is non-increasing (rounding is
    monotone), so cs_i - cs_j ≤ 0 for i ≥ j also after rounding and no clamp is needed.
    Not differentiable by autograd (in-place); :class:`IntraChunk` has its own backward.

    Args:
        cs: (..., T) inclusive cumulative sums of a = Δ·A ≤ 0 (any strides).

    Returns:
        (..., T, T) decay mask, zero above the diagonal.
    """
    T = cs.shape[-1]
    bias = torch.full((T, T), -torch.inf, dtype=cs.dtype, device=cs.device).triu_(1)
    return torch.sub(cs[..., :, None], cs[..., None, :]).add_(bias).exp_()
