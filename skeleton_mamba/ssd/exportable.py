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
    xd = (xc * delta[..., None]).view(b, L, G, R, P)  # Δ x
    Bc, Cc = B.to(ct), C.to(ct)  # (b, L, G, N)
    cs = (delta.to(torch.float64) * A.to(torch.float64)).cumsum(dim=1).view(b, L, G, R)  # float64
    cs_h = cs.permute(0, 2, 3, 1)  # (b, G, R, L)
    causal = torch.ones(L, L, dtype=torch.bool, device=x.device).tril()
    zero = torch.zeros((), dtype=cs.dtype, device=x.device)
    # exp(cs_i - cs_j) below the diagonal, 0 above it: the difference is selected before the exp, as
    # it is positive (and may overflow) above the diagonal.
    mask = torch.exp(torch.where(causal, cs_h[..., :, None] - cs_h[..., None, :], zero))
    mask = torch.where(causal, mask, zero).to(ct)  # (b, G, R, L, L)
    cb = torch.matmul(Cc.transpose(1, 2), Bc.permute(0, 2, 3, 1))  # C Bᵀ once per group, (b, G, L, L)
    rhs = xd.permute(0, 2, 3, 1, 4)  # (b, G, R, L, P)
    y = torch.matmul(mask * cb[:, :, None], rhs)  # (b, G, R, L, P)
    h0 = None
    if initial_state is not None:
        h0 = initial_state.to(ct).view(b, G, R, P, N)
        from_start = torch.exp(cs_h).to(ct)[..., None]  # exp(cs_i), (b, G, R, L, 1)
        y = y + from_start * torch.matmul(Cc.transpose(1, 2)[:, :, None], h0.transpose(-1, -2))
    y = apply_skip(y.permute(0, 3, 1, 2, 4).reshape(b, L, H, P), xc, D).to(x.dtype)
    if not return_final_state:
        return y
    last = cs_h[..., -1:]  # cs_{L-1}, (b, G, R, 1)
    to_end = torch.exp(last - cs_h).to(ct)  # (b, G, R, L)
    final = torch.matmul((rhs * to_end[..., None]).transpose(-1, -2), Bc.transpose(1, 2)[:, :, None])
    if h0 is not None:
        final = final + torch.exp(last).to(ct)[..., None] * h0
    return y, final.reshape(b, H, P, N)
