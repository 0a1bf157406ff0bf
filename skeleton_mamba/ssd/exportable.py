"""The SSD as one graph of tensor operations, for ``torch.export`` and ONNX ([Mamba-2] quadratic form).

The other matrix forms loop in Python over chunks, blocks or tiles whose number follows from the
length and the batch, run hand-written autograd functions and check their inputs for non-finite values
(a data-dependent branch), so a traced graph would be fixed to one length and batch. Here nothing
depends on the sizes but the shapes of the tensors, and no size is divided (a chunk count
ceil(L / Q) puts guards on the length into a traced graph), so one exported graph serves every batch
and length. Per head h of B/C group g, with cs the inclusive cumulative sum (float64) of a = Δ·A over
the whole sequence:

    Y = (Lmask ∘ C Bᵀ)(Δ ⊙ X) + exp(cs) ⊙ (C h0) + D ⊙ X,    Lmask_ij = exp(cs_i - cs_j) for i ≥ j, else 0,
    final state = Σ_j exp(cs_{L-1} - cs_j) (Δ_j x_j) ⊗ B_j + exp(cs_{L-1}) h0.

Every decay is exp of a float64 difference ≤ 0 (a ≤ 0), rounded once to the compute dtype (fp32, fp64
for fp64), so nothing overflows and the mask is exact to that rounding. Cost O(L²) per head and
sequence (the L×L mask: 8·L² bytes per head and sequence in float64): for the frame-wise scans' short
sequences and the Temporal Scan up to a few hundred frames. Inference only. As in compiled code
(:mod:`skeleton_mamba.ssd.non_finite`), non-finite inputs are not confined to later steps.
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.discretize import NO_DT_LIMIT, apply_skip, compute_dtype, discretize_dt


def masked_quadratic(xd: torch.Tensor, cs: torch.Tensor, B: torch.Tensor, C: torch.Tensor) -> torch.Tensor:
    """(Lmask ∘ C Bᵀ)(Δ ⊙ X) over whole sequences from a zero state, per head h of B/C group g.

    Lmask_ij = exp(cs_i - cs_j) for i ≥ j, else 0: the difference of the float64 cumulative sums is
    masked to -inf above the diagonal before the exp (there it is positive and may overflow) and the mask
    rounded once to xd's dtype. C Bᵀ is formed once per group. The form of :func:`ssd_exportable` and of
    the frame path (:func:`skeleton_mamba.runtime.frame_ops.short_mix`). Inference only (in-place
    temporaries).

    Args:
        xd: (b, L, H, P) Δ ⊙ x in the compute dtype.
        cs: (b, H, L) the inclusive cumulative sums of a = Δ·A over each sequence (float64).
        B: (b, L, G, N) the input projections in xd's dtype; head h reads group h // (H // G).
        C: (b, L, G, N) the output projections, grouped as B.

    Returns:
        (b, L, H, P) in xd's dtype.

    Examples:
        >>> import torch
        >>> xd, B, C = torch.ones(1, 2, 1, 1), torch.ones(1, 2, 1, 1), torch.ones(1, 2, 1, 1)
        >>> cs = torch.tensor([[[-1.0, -1.0]]], dtype=torch.float64)  # a = (-1, 0): no decay at step 2
        >>> masked_quadratic(xd, cs, B, C).flatten().tolist()  # y_1 = 1, y_2 = exp(0) 1 + 1
        [1.0, 2.0]
    """
    b, L, H, P = xd.shape
    G = B.shape[2]
    upper = torch.ones(L, L, dtype=torch.bool, device=xd.device).triu(1)
    mask = (cs[..., :, None] - cs[..., None, :]).masked_fill_(upper, -torch.inf).exp_().to(xd.dtype)
    cb = torch.matmul(C.transpose(1, 2), B.permute(0, 2, 3, 1))  # (b, G, L, L)
    weight = mask.view(b, G, H // G, L, L).mul_(cb[:, :, None]).view(b, H, L, L)
    return torch.matmul(weight, xd.transpose(1, 2)).transpose(1, 2)  # (b, L, H, P)


def ssd_exportable(
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
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """SSD by the quadratic form over the whole sequence; arguments and results as :func:`ssd_recurrence`.

    Args:
        x: (b, L, H, P); dt: (b, L, H); A: (H,); B, C: (b, L, G, N); D: (H,) or (H, P) or ``None``;
        initial_state: (b, H, P, N) or ``None`` (zeros).

    Returns:
        y (b, L, H, P) in x's dtype, and the final state (b, H, P, N) in the compute dtype when
        ``return_final_state``.
    """
    b, L, H, P = x.shape
    G, N = B.shape[2], B.shape[3]
    R = H // G
    ct = compute_dtype(x)
    delta = discretize_dt(dt, dt_bias, dt_softplus, dt_limit, ct)  # (b, L, H)
    xc = x.to(ct)
    xd = xc * delta[..., None]  # Δ x, (b, L, H, P)
    Bc, Cc = B.to(ct), C.to(ct)  # (b, L, G, N)
    cs = (delta.to(torch.float64) * A.to(torch.float64)).cumsum(dim=1).transpose(1, 2)  # (b, H, L) float64
    y = masked_quadratic(xd, cs, Bc, Cc)
    h0 = None
    if initial_state is not None:
        h0 = initial_state.to(ct).view(b, G, R, P, N)
        from_start = torch.exp(cs).to(ct).view(b, G, R, L, 1)  # exp(cs_i)
        y_h0 = from_start * torch.matmul(
            Cc.transpose(1, 2)[:, :, None], h0.transpose(-1, -2)
        )  # (b, G, R, L, P)
        y = y + y_h0.permute(0, 3, 1, 2, 4).reshape(b, L, H, P)
    y = apply_skip(y, xc, D).to(x.dtype)
    if not return_final_state:
        return y
    last = cs[..., -1:]  # cs_{L-1}, (b, H, 1)
    to_end = torch.exp(last - cs).to(ct).view(b, G, R, L, 1)  # (b, G, R, L, 1)
    rhs = xd.view(b, L, G, R, P).permute(0, 2, 3, 1, 4)  # (b, G, R, L, P)
    final = torch.matmul((rhs * to_end).transpose(-1, -2), Bc.transpose(1, 2)[:, :, None])  # (b, G, R, P, N)
    if h0 is not None:
        final = final + torch.exp(last).to(ct).view(b, G, R, 1, 1) * h0
    return y, final.reshape(b, H, P, N)
