"""The chunked SSD's three steps as one function with a hand-written backward ([Mamba-2] SSD, chunked form).

Per chunk k of length Q and head h of B/C group g: cs is the inclusive cumulative sum (float64) of the log
decays a = Δ·A inside the chunk and T_k = cs_{Q-1} its total. As in :mod:`~skeleton_mamba.ssd.intra_chunk`,
cs = hi + lo with hi its rounding to the compute dtype, r = exp(lo), c = exp(-lo), and Xd = c ⊙ Δ ⊙ X
(Q×P). Then

1. the chunk's state from zero:   s_k = Be Xd,   Be = (exp(T_k - hi) ⊙ B)ᵀ                      (N×P)
2. the states entering chunks:    S_0 = h0,  S_{k+1} = exp(T_k) S_k + s_k  (a scan over the chunks)
3. the outputs:                   Y' = W Xd + Ce S_k,   W = E ∘ C Bᵀ,  E_ij = exp(hi_i - hi_j) (i ≥ j),
                                  Ce = exp(hi) ⊙ C,     Y = r ⊙ Y' + D ⊙ X

which is Y_q = Σ_{j≤q} exp(cs_q - cs_j) (C_q·B_j) Δ_j X_j + exp(cs_q) C_q S_k + D X_q and
s_k = Σ_j exp(T_k - cs_j) Δ_j X_j ⊗ B_j: the chunked form of ``mamba_ssm/modules/ssd_minimal.py``, with
the float64 decays entering the compute dtype only through r and c. The states are kept as N×P (the
transpose of the usual P×N), so steps 1 and 3 are batched products of the layouts their factors already
have: no separate scaling passes for the states or their outputs, no layout copies, and the gradients of
both steps flow into one dXd. Decay factors below the compute dtype's smallest normal number (1.2e-38 in
fp32) are set to zero (:func:`decay_factor`): the terms they scale lie far below the rounding of any output
of ordinary size, and subnormal operands make CPU arithmetic many times slower.

Backward, with dY' = r ⊙ dY and G_k = dL/dS_k (the scan run backwards from G_c = dL/dS_final):

    dS_in = Ceᵀ dY',   ds_k = G_{k+1} = dS_in[k+1] + exp(T_{k+1}) G_{k+2},   dh0 = G_0,
    dXd = Wᵀ dY' + Beᵀ ds,   dW = (dY' Xdᵀ) ∘ E,   dCe = dY' S_kᵀ,   dBe = ds Xdᵀ,
    dC = Σ_heads (dW B + exp(hi) ⊙ dCe),   dB = Σ_heads (dWᵀ C + (exp(T - hi) ⊙ dBe)ᵀ),
    dX = c Δ ⊙ dXd + D ⊙ dY,   dΔ = c ⊙ Σ_p X ⊙ dXd,   dD = Σ X ⊙ dY,

and the gradient of the log decays, one sum per way a_m enters (m a position of chunk k):

    da_m = Σ_{i ≥ m > j} M_ij      W_ij holds a_{j+1..i};  M = dW' ∘ CB, dW' per head (decay_mask_backward)
         + Σ_{i ≥ m} q_i           Ce_i holds cs_i = a_{0..i};  q = Σ_p dY' ⊙ (Ce S_k)
         + Σ_{j < m} g_j           Be_j holds T - cs_j = a_{j+1..Q-1};  g = Σ_p Xd ⊙ (Beᵀ ds_k)
         + d_k Σ G_{k+1} ⊙ S_k     the chunk's decay exp(T_k) of step 2 holds every a_m

(every factor exp(±cs) is its own derivative). Each term is summed over exactly
the entries that hold a_m. Written as per-position gradients of cs followed by a cumulative sum, the row
and column sums of M and the Be term of the last position would cancel to within their rounding, which
under fast decay is far larger than the gradient (the fp32 gradients of A and dt would be 10² to 10³
times less accurate than the recurrence's).

Memory: the Q×Q and N×Q factors of all chunks are kept for the backward (with Q = P = N, about eight
tensors the size of X); unlike the quadratic form's :func:`~skeleton_mamba.ssd.intra_chunk.intra_chunk`
nothing is tiled, the sizes grow linearly with the length.
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.discretize import sum_over_positions
from skeleton_mamba.ssd.intra_chunk import column_weights, compute_inputs, split_cumsum
from skeleton_mamba.ssd.precision import full_precision
from skeleton_mamba.ssd.segsum import decay_mask, decay_mask_backward
from skeleton_mamba.ssd.state_scan import decay_factor, scan_states, scan_states_backward


def _sum_over_group_heads(t: torch.Tensor, groups: int) -> torch.Tensor:
    """(n, H, ...) -> (n, G, ...): the sum over the H // G heads of every B/C group."""
    n, H = t.shape[:2]
    if H == groups:
        return t
    return t.view(n, groups, H // groups, *t.shape[2:]).sum(2)


class ChunkScan(torch.autograd.Function):
    """See the module docstring. Layouts: x (n, Q, H, P) for n = b·c chunks (sequence-major), delta
    (n, Q, H), a (n, H, Q) (float64 or x's dtype), B, C (n, Q, G, N), D (H, P) or None, h0 (b, H, N, P)
    -> y (n, Q, H, P), final state (b, H, N, P)."""

    @staticmethod
    def forward(ctx, x, delta, a, B, C, D, h0):
        n, Q, H, P = x.shape
        G, N = B.shape[2], B.shape[3]
        R, b = H // G, h0.shape[0]
        c = n // b
        cs = a.cumsum(-1)
        hi, row, col = split_cumsum(cs, x.dtype)  # (n, H, Q)
        wcol = column_weights(delta, col)  # Δ_j c_j
        xd = torch.mul(x.transpose(1, 2), wcol[..., None], out=x.new_empty(n, H, Q, P))
        total = cs[..., -1:]  # (n, H, 1) in cs's dtype
        e = decay_factor(total - hi.to(cs.dtype), x.dtype)  # (n, H, Q)
        Be = torch.mul(
            e.view(n, G, R, 1, Q), B.permute(0, 2, 3, 1)[:, :, None], out=x.new_empty(n, G, R, N, Q)
        ).reshape(n, H, N, Q)
        d = decay_factor(total.reshape(b, c, H), x.dtype)
        S_in, final = scan_states(torch.matmul(Be, xd).view(b, c, H, N, P), d, h0)
        E = decay_mask(hi)  # (n, H, Q, Q)
        CB = torch.matmul(C.transpose(1, 2), B.permute(0, 2, 3, 1))  # (n, G, Q, Q), shared by R heads
        W = torch.mul(E.view(n, G, R, Q, Q), CB[:, :, None]).view(n, H, Q, Q)
        f = decay_factor(hi, x.dtype)
        Ce = torch.mul(f.view(n, G, R, Q, 1), C.transpose(1, 2)[:, :, None]).view(n, H, Q, N)
        y_state = torch.matmul(Ce, S_in.view(n, H, N, P))  # (n, H, Q, P), kept for the gradient of a
        y_in = torch.baddbmm(y_state.view(n * H, Q, P), W.view(n * H, Q, Q), xd.view(n * H, Q, P))
        y_in = y_in.view(n, H, Q, P)
        y = torch.empty_like(x)
        if row is None:
            y.copy_(y_in.transpose(1, 2))
        else:
            torch.mul(y_in.transpose(1, 2), row.transpose(1, 2)[..., None], out=y)
        if D is not None:
            y.addcmul_(x, D)
        ctx.a_dtype = a.dtype
        ctx.save_for_backward(x, delta, row, col, B, C, D, xd, E, CB, W, Be, Ce, e, f, d, S_in, y_state)
        return y, final

    @staticmethod
    @full_precision  # backward() may be called inside an autocast region
    def backward(ctx, dy, dfinal):
        x, delta, row, col, B, C, D, xd, E, CB, W, Be, Ce, e, f, d, S_in, y_state = ctx.saved_tensors
        n, Q, H, P = x.shape
        G, N = B.shape[2], B.shape[3]
        R = H // G
        b, c = d.shape[:2]
        wcol = column_weights(delta, col)
        dys = x.new_empty(n, H, Q, P)
        if row is None:
            dys.copy_(dy.transpose(1, 2))
        else:
            torch.mul(dy.transpose(1, 2), row[..., None], out=dys)
        S_flat = S_in.reshape(n, H, N, P)
        ds, dh0 = scan_states_backward(torch.matmul(Ce.transpose(-1, -2), dys).view(b, c, H, N, P), d, dfinal)
        ds_flat = ds.reshape(n, H, N, P)
        bds = torch.matmul(Be.transpose(-1, -2), ds_flat)  # (n, H, Q, P): Beᵀ ds
        Wt = W.view(n * H, Q, Q).transpose(-1, -2)
        dxd = torch.baddbmm(bds.view(n * H, Q, P), Wt, dys.view(n * H, Q, P)).view(n, H, Q, P)
        # W, Ce and Be are not needed any more: their gradients take their storage.
        dW = torch.matmul(dys, xd.transpose(-1, -2), out=W).mul_(E)
        dCe = torch.matmul(dys, S_flat.transpose(-1, -2), out=Ce).mul_(f[..., None])
        dBe = torch.matmul(ds_flat, xd.transpose(-1, -2), out=Be).mul_(e[:, :, None])
        da = None
        if ctx.needs_input_grad[2]:  # the state terms of da (module docstring)
            q = torch.linalg.vecdot(dys, y_state)  # Σ_n C dCe = Σ_p dY' ⊙ (Ce S), (n, H, Q)
            g = torch.linalg.vecdot(xd, bds)  # Σ_n B dBe = Σ_p Xd ⊙ (Beᵀ ds)
            da = q.flip(-1).cumsum(-1).flip(-1)  # Σ_{i ≥ m} q_i
            da[..., 1:] += g[..., :-1].cumsum(-1)  # Σ_{j < m} g_j
            da += (d * torch.linalg.vecdot(ds.flatten(3), S_in.flatten(3))).view(n, H, 1)
        dCB, dCe, dBe = (_sum_over_group_heads(t, G) for t in (dW, dCe, dBe))
        dC_t = torch.matmul(dCB, B.transpose(1, 2)).add_(dCe)  # (n, G, Q, N)
        dB_t = torch.matmul(dCB.transpose(-1, -2), C.transpose(1, 2)).add_(dBe.transpose(-1, -2))
        if da is not None:  # dCB is used: dW becomes M = W ∘ ∂L/∂W = dW ∘ CB in place
            da += decay_mask_backward(dW.view(n, G, R, Q, Q).mul_(CB[:, :, None]).view(n, H, Q, Q))
            da = da.to(ctx.a_dtype)
        # (n, H, Q): Σ_p X dXd, the product written into dY's buffer (no longer read)
        u = torch.mul(x.transpose(1, 2), dxd, out=dys).sum(-1)
        ddelta = u if col is None else u * col
        dx = torch.mul(dxd.transpose(1, 2), wcol.transpose(1, 2)[..., None], out=torch.empty_like(x))
        if D is not None:
            dx.addcmul_(dy, D)
        dD = None
        if D is not None and ctx.needs_input_grad[5]:
            dD = sum_over_positions(dy, x, scratch=dys)  # the product goes to dY's buffer, free again
        return (dx, ddelta.transpose(1, 2), da, dB_t.transpose(1, 2), dC_t.transpose(1, 2), dD, dh0)


@torch.compiler.disable(reason="ChunkScan runs eagerly (its hand-written backward is faster than inductor)")
def chunk_scan(
    x: torch.Tensor,
    delta: torch.Tensor,
    a: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    D: torch.Tensor | None,
    h0: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """SSD outputs and final state of b sequences of c chunks each, in x's dtype.

    Args:
        x: (n, Q, H, P) inputs, n = b·c chunks, those of one sequence consecutive.
        delta: (n, Q, H) step sizes Δ.
        a: (n, H, Q) log decays a = Δ·A, float64 (or x's dtype, then the decays carry the rounding
            error of their cumulative sums; see intra_chunk.py).
        B: (n, Q, G, N) input projections; head h reads group h // (H // G).
        C: (n, Q, G, N) output projections, grouped as B.
        D: (H, P) skip weights or ``None``.
        h0: (b, H, N, P) the state entering each sequence (N×P, the transpose of ``ssd``'s states).

    Returns:
        y (n, Q, H, P), final state (b, H, N, P). Under ``torch.compile`` this runs eagerly (a graph
        break): its hand-written backward is faster than inductor's fusion of the same computation.
    """
    a, (x, delta, B, C, D, h0) = compute_inputs(x.dtype, a, x, delta, B, C, D, h0)
    return ChunkScan.apply(x, delta, a, B, C, D, h0)
