"""The quadratic ("attention-like") SSD form inside chunks, with a hand-written backward.

For each chunk (step 1, diagonal blocks, of ``mamba_ssm/modules/ssd_minimal.py``), per head h of B/C group g:

    Y = (Lmask ∘ C Bᵀ)(Δ ⊙ X) + Y_off + D ⊙ X,      Lmask_ij = exp(cs_i - cs_j) for i ≥ j, else 0,

with cs the inclusive cumulative sum (in float64) of the log decays a = Δ·A inside the chunk and Y_off
an optional term added by the caller (the inter-chunk contribution). C·Bᵀ is formed once per group and
shared by its heads.

Accuracy: ``a`` arrives in float64, and so does its cumulative sum cs. Rounding cs to fp32 would put
an error of u·|cs_i| (u = 2^-24) on every mask entry of row i — 1.5e-5 relative at |cs| = 250, more
than the rest of the fp32 computation together. So cs = hi + lo with hi = fp32(cs), and
exp(cs_i - cs_j) = exp(hi_i - hi_j) · r_i · c_j with r = exp(lo), c = exp(-lo) (|lo| ≤ u|cs|/2):
the Q×Q mask is formed in fp32 from hi only (an fp32 difference is correctly rounded), c is folded
into the column weights Xd' = c ⊙ Δ ⊙ X and r into the rows of the output, both O(Q·P) work.

Backward, with W' = exp(hi_i - hi_j)·CB_ij (causal), Xd' = c ⊙ Δ ⊙ X, Y' = W' Xd' (Y_in = r ⊙ Y'),
dY' = r ⊙ dY (so that W = diag(r) W' diag(c) never has to be formed):
    dXd' = W'ᵀ dY',  dCB = Σ_{heads of g} (dY' Xd'ᵀ) ∘ exp(hi_i - hi_j) (causal),
    dC = dCB B,  dB = dCBᵀ C,  u_j = Σ_p X_jp dXd'_jp,  dΔ = c ⊙ u,  dX = c ⊙ Δ ⊙ dXd' + D ⊙ dY,
    da_k = Σ_{i ≥ k > j} M_ij,  M = W ∘ ∂L/∂W = dW' ∘ CB  (dW' = (dY' Xd'ᵀ) ∘ exp(hi_i - hi_j) per head;
             W_ij holds a_{j+1} + ... + a_i, see :func:`~skeleton_mamba.ssd.segsum.decay_mask_backward`),
    dD = Σ X ⊙ dY,  dY_off = dY.

The gradient of a is summed over the Q×Q entries whose segment holds a_k, never as the difference of the
row and column sums of M (Σ_p dY' Y' - Σ_p Xd' dXd' per position, then a cumulative sum): that difference
keeps the rounding of the diagonal terms, which under fast decay (|Δ·A| ≈ 2 per step) is far larger than
the gradient itself: the fp32 gradients of A and dt would be 10² to 10⁴ times less accurate than the
recurrence's.

Speed on CPU: the Q×Q tensors (the mask, C Bᵀ and W) are formed for at most ``TILE_ELEMENTS``
entries at a time. When all chunks fit in one tile (every benchmark size) the mask and W are kept
for the backward; larger inputs run tile by tile with reused buffers and the backward recomputes
them, so memory stays bounded. Tiles are deliberately large: every operation is a thread fork/join,
so many cache-sized tiles cost more in synchronisation than they save.
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.discretize import sum_over_positions
from skeleton_mamba.ssd.precision import full_precision
from skeleton_mamba.ssd.segsum import decay_mask, decay_mask_backward

# Most Q×Q entries (chunks · heads · Q²) per tile: 64 MB per buffer in fp32.
TILE_ELEMENTS = 1 << 24


def _tiles(n: int, per_item: int) -> list[tuple[int, int]]:
    step = max(1, TILE_ELEMENTS // max(1, per_item))
    return [(i, min(n, i + step)) for i in range(0, n, step)]


def split_cumsum(
    cs: torch.Tensor, dtype: torch.dtype
) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
    """hi = cs rounded to ``dtype`` and the factors r = exp(cs - hi), c = exp(hi - cs) in ``dtype``.

    r and c are ``None`` when cs already has ``dtype`` (nothing was rounded).
    """
    hi = cs.to(dtype)
    if cs.dtype == dtype:
        return hi, None, None
    lo = cs - hi.to(cs.dtype)
    return hi, lo.exp().to(dtype), lo.neg().exp().to(dtype)


def column_weights(delta: torch.Tensor, col: torch.Tensor | None) -> torch.Tensor:
    """Δ_j c_j, the column factor of Xd' = c ⊙ Δ ⊙ X: (n, H, Q) from delta (n, Q, H) and c (n, H, Q)."""
    return delta.transpose(1, 2) if col is None else delta.transpose(1, 2) * col


def compute_inputs(
    dtype: torch.dtype, a: torch.Tensor, *tensors: torch.Tensor | None
) -> tuple[torch.Tensor, list[torch.Tensor | None]]:
    """The log decays a contiguous in float64 (kept) or else in ``dtype``; the tensors contiguous in
    ``dtype``."""
    a = a.contiguous() if a.dtype == torch.float64 else a.to(dtype).contiguous()
    return a, [t if t is None else t.to(dtype).contiguous() for t in tensors]


def _weights(hi, B, C, E, CB, W):
    """Fill the tile buffers: CB = C Bᵀ (s, G, Q, Q), E = exp(hi_i - hi_j) causal (s, H, Q, Q) and
    W = E ∘ CB (s, H, Q, Q); W may be E itself (then E is overwritten)."""
    s, G, Q = CB.shape[0], CB.shape[1], CB.shape[2]
    R = E.shape[1] // G
    torch.matmul(C.transpose(1, 2), B.transpose(1, 2).transpose(-1, -2), out=CB)
    decay_mask(hi, out=E)
    torch.mul(E.view(s, G, R, Q, Q), CB[:, :, None], out=W.view(s, G, R, Q, Q))
    return W


class IntraChunk(torch.autograd.Function):
    """See the module docstring. Layouts: x (n, Q, H, P), delta (n, Q, H), a (n, H, Q) (float64 or x's
    dtype), B, C (n, Q, G, N), D (H, P) or None, y_off (n, Q, H, P) or None -> y (n, Q, H, P)."""

    @staticmethod
    def forward(ctx, x, delta, a, B, C, D, y_off):
        n, Q, H, P = x.shape
        G = B.shape[2]
        hi, row, col = split_cumsum(a.cumsum(-1), x.dtype)  # (n, H, Q)
        wcol = column_weights(delta, col)  # Δ_j c_j
        xd, y = x.new_empty(n, H, Q, P), torch.empty_like(x)
        y_in = torch.empty_like(xd)
        tiles = _tiles(n, H * Q * Q)
        m = tiles[0][1]
        keep = len(tiles) == 1  # one tile: keep E and W for the backward
        E, CB = x.new_empty(m, H, Q, Q), x.new_empty(m, G, Q, Q)
        Wbuf = torch.empty_like(E) if keep else E
        for r0, r1 in tiles:
            t, s = slice(r0, r1), r1 - r0
            torch.mul(x[t].transpose(1, 2), wcol[t, :, :, None], out=xd[t])
            W = _weights(hi[t], B[t], C[t], E[:s], CB[:s], Wbuf[:s])
            torch.matmul(W, xd[t], out=y_in[t])
            if row is not None:
                y_in[t].mul_(row[t, :, :, None])
            # the head-major result transposed into y in the same pass as the first term added to it
            if y_off is not None:
                torch.add(y_in[t].transpose(1, 2), y_off[t], out=y[t])
                if D is not None:
                    y[t].addcmul_(x[t], D)
            elif D is not None:
                torch.addcmul(y_in[t].transpose(1, 2), x[t], D, out=y[t])
            else:
                y[t].copy_(y_in[t].transpose(1, 2))
        ctx.a_dtype = a.dtype
        ctx.save_for_backward(x, delta, hi, row, col, B, C, D, xd, *((E, Wbuf, CB) if keep else ()))
        return y

    @staticmethod
    @full_precision  # backward() may be called inside an autocast region
    def backward(ctx, dy):
        x, delta, hi, row, col, B, C, D, xd, *kept = ctx.saved_tensors
        n, Q, H, P = x.shape
        G = B.shape[2]
        R = H // G
        wcol = column_weights(delta, col)
        dys, dxd = torch.empty_like(xd), torch.empty_like(xd)
        dx = torch.empty_like(x)
        ddelta, da = x.new_empty(n, H, Q), x.new_empty(n, H, Q)
        dB_t = B.new_empty(n, G, Q, B.shape[3])
        dC_t = torch.empty_like(dB_t)
        want_dD = D is not None and ctx.needs_input_grad[5]
        dD = torch.zeros_like(D) if want_dD else None
        tiles = _tiles(n, H * Q * Q)
        m = tiles[0][1]
        if kept:
            E, W, CB = kept
        else:
            E, W, CB = x.new_empty(m, H, Q, Q), x.new_empty(m, H, Q, Q), x.new_empty(m, G, Q, Q)
        for r0, r1 in tiles:
            t, s = slice(r0, r1), r1 - r0
            if row is None:
                dys[t].copy_(dy[t].transpose(1, 2))
            else:
                torch.mul(dy[t].transpose(1, 2), row[t, :, :, None], out=dys[t])
            Wt = W if kept else _weights(hi[t], B[t], C[t], E[:s], CB[:s], W[:s])
            torch.matmul(Wt.transpose(-1, -2), dys[t], out=dxd[t])
            # W is not needed any more: dW takes its storage (a second backward through this graph
            # would then fail loudly on the version check of a kept W instead of reading it).
            dW = torch.matmul(dys[t], xd[t].transpose(-1, -2), out=Wt).mul_(E[:s])  # (dY' Xd'ᵀ) ∘ E
            dCB = dW.view(s, G, R, Q, Q).sum(2) if R > 1 else dW
            torch.matmul(dCB, B[t].transpose(1, 2), out=dC_t[t])
            torch.matmul(dCB.transpose(-1, -2), C[t].transpose(1, 2), out=dB_t[t])
            # dCB is used: dW becomes M = W ∘ ∂L/∂W = dW ∘ CB in place
            if ctx.needs_input_grad[2]:
                M = dW.view(s, G, R, Q, Q).mul_(CB[:s, :, None]).view(s, H, Q, Q)
                da[t] = decay_mask_backward(M)
            # (s, H, Q): Σ_p X dXd', the product written into dY's buffer (no longer read)
            u = torch.mul(x[t].transpose(1, 2), dxd[t], out=dys[t]).sum(-1)
            if col is None:
                ddelta[t].copy_(u)
            else:
                torch.mul(u, col[t], out=ddelta[t])
            dxd[t].mul_(wcol[t, :, :, None])  # dXd' is used: it becomes c ⊙ Δ ⊙ dXd' in place
            if D is not None:
                torch.addcmul(dxd[t].transpose(1, 2), dy[t], D, out=dx[t])
            else:
                dx[t].copy_(dxd[t].transpose(1, 2))
            if want_dD:  # the product goes to dY's buffer, free again
                dD += sum_over_positions(dy[t], x[t], scratch=dys[t])
        dy_off = dy if ctx.needs_input_grad[6] else None
        da = da.to(ctx.a_dtype) if ctx.needs_input_grad[2] else None
        return (dx, ddelta.transpose(1, 2), da, dB_t.transpose(1, 2), dC_t.transpose(1, 2), dD, dy_off)


def intra_chunk(
    x: torch.Tensor,
    delta: torch.Tensor,
    a: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    D: torch.Tensor | None = None,
    y_off: torch.Tensor | None = None,
) -> torch.Tensor:
    """SSD output of independent chunks from a zero entering state, plus ``y_off`` and D ⊙ x.

    Args:
        x: (n, Q, H, P) inputs of n chunks of length Q.
        delta: (n, Q, H) step sizes Δ.
        a: (n, H, Q) log decays a = Δ·A, in float64 (or in x's dtype, then the mask carries the
            rounding error of their cumulative sum, see the module docstring).
        B: (n, Q, G, N) input projections; head h reads group h // (H // G).
        C: (n, Q, G, N) output projections, grouped as B.
        D: (H, P) skip weights or ``None``.
        y_off: (n, Q, H, P) extra term (the contribution of the earlier blocks) or ``None``.

    Returns:
        y (n, Q, H, P) = (Lmask ∘ C Bᵀ)(Δ ⊙ x) + y_off + D ⊙ x, all in x's dtype.
    """
    a, (x, delta, B, C, D, y_off) = compute_inputs(x.dtype, a, x, delta, B, C, D, y_off)
    return IntraChunk.apply(x, delta, a, B, C, D, y_off)
