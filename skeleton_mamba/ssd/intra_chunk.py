"""The quadratic ("attention-like") SSD form inside chunks, with a hand-written, tiled backward.

For each chunk (reference §2 item 4, §3 step 1), per head h of B/C group g:

    Y = (Lmask ∘ C Bᵀ)(Δ ⊙ X) + Y_off + D ⊙ X,      Lmask_ij = exp(cs_i - cs_j) for i ≥ j, else 0,

with cs the inclusive cumulative sum of a = Δ·A inside the chunk and Y_off an optional term added
by the caller (the inter-chunk contribution). C·Bᵀ is formed once per group and shared by its heads.

Speed (CPU): the Q×Q matrices (Lmask, W = Lmask ∘ CB, dW) are never materialised for the whole
batch. The chunks are processed in tiles small enough to stay in cache, and the backward recomputes
Lmask and W tile by tile instead of saving them (nothing of size Q×Q is kept between forward and
backward). Large fresh allocations are avoided: on Linux every allocation above 32 MiB is a fresh
mmap whose first touch page-faults, which costs more than the arithmetic here.

Backward, with W = Lmask ∘ CB (per head) and Xd = Δ ⊙ X:
    dXd = Wᵀ dY,  dW = dY Xdᵀ,  dCB = Σ_{heads of g} dW ∘ Lmask,  dC = dCB B,  dB = dCBᵀ C,
    d cs_i = Σ_j G_ij - Σ_k G_ki with G = dW ∘ W   (∂W_ij/∂cs_i = W_ij, ∂W_ij/∂cs_j = -W_ij),
    dX = Δ ⊙ dXd + D ⊙ dY,  dΔ = Σ_p X ⊙ dXd,  dD = Σ X ⊙ dY,  dY_off = dY.
"""

from __future__ import annotations

import torch

# Number of Q×Q mask entries processed per tile (4 buffers of this many fp32 values stay in cache).
TILE_ELEMENTS = 1 << 19


def _tiles(n: int, per_item: int):
    step = max(1, TILE_ELEMENTS // max(1, per_item))
    return [(i, min(n, i + step)) for i in range(0, n, step)]


def _causal_bias(Q: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """(Q, Q) with 0 on and below the diagonal and -inf above: exp(segsum + bias) is causal."""
    return torch.full((Q, Q), -torch.inf, dtype=dtype, device=device).triu_(1)


def _mask_and_weights(cs, CB, bias, E, W):
    """E = Lmask (s, H, Q, Q) and W = E ∘ CB written into the buffers E, W; returns (E, W)."""
    s, H, Q = cs.shape
    G = CB.shape[1]
    torch.sub(cs[..., :, None], cs[..., None, :], out=E)
    E.add_(bias).exp_()
    torch.mul(E.view(s, G, H // G, Q, Q), CB[:, :, None], out=W.view(s, G, H // G, Q, Q))
    return E, W


class IntraChunk(torch.autograd.Function):
    """See the module docstring. Layouts: x (n, Q, H, P), delta (n, Q, H), cs (n, H, Q),
    B, C (n, Q, G, N), D (H, P) or None, y_off (n, H, Q, P) or None -> y (n, Q, H, P)."""

    @staticmethod
    def forward(ctx, x, delta, cs, B, C, D, y_off):
        n, Q, H, P = x.shape
        y = torch.empty_like(x)
        bias = _causal_bias(Q, x.dtype, x.device)
        bufs = None
        for r0, r1 in _tiles(n, H * Q * Q):
            s = r1 - r0
            if bufs is None or bufs[0].shape[0] != s:
                bufs = (x.new_empty(s, H, Q, Q), x.new_empty(s, H, Q, Q), x.new_empty(s, H, Q, P))
            E, W, xd = bufs
            torch.mul(x[r0:r1].transpose(1, 2), delta[r0:r1].transpose(1, 2)[..., None], out=xd)
            Cs, Bs = C[r0:r1].transpose(1, 2), B[r0:r1].transpose(1, 2)  # (s, G, Q, N)
            CB = torch.matmul(Cs, Bs.transpose(-1, -2))  # (s, G, Q, Q)
            E, W = _mask_and_weights(cs[r0:r1], CB, bias, E, W)
            yt = torch.matmul(W, xd) if y_off is None else torch.baddbmm(
                y_off[r0:r1].reshape(s * H, Q, P), W.view(s * H, Q, Q), xd.view(s * H, Q, P)).view(s, H, Q, P)
            out = y[r0:r1]
            if D is None:
                out.copy_(yt.transpose(1, 2))
            else:
                torch.addcmul(yt.transpose(1, 2), x[r0:r1], D, out=out)
        ctx.save_for_backward(x, delta, cs, B, C, D)
        ctx.has_y_off = y_off is not None
        return y

    @staticmethod
    def backward(ctx, dy):
        x, delta, cs, B, C, D = ctx.saved_tensors
        n, Q, H, P = x.shape
        G = B.shape[2]
        R = H // G
        need = ctx.needs_input_grad
        dx, ddelta, dcs = torch.empty_like(x), torch.empty_like(delta), torch.empty_like(cs)
        dB, dC = torch.empty_like(B), torch.empty_like(C)
        dD = torch.zeros_like(D) if D is not None and need[5] else None
        dy_off = x.new_empty(n, H, Q, P) if ctx.has_y_off and need[6] else None
        bias = _causal_bias(Q, x.dtype, x.device)
        bufs = None
        for r0, r1 in _tiles(n, H * Q * Q):
            s = r1 - r0
            if bufs is None or bufs[0].shape[0] != s:
                bufs = tuple(x.new_empty(s, H, Q, Q) for _ in range(3)) + tuple(
                    x.new_empty(s, H, Q, P) for _ in range(2))
            E, W, dW, xd, dys = bufs
            xs, ds, dy_s = x[r0:r1], delta[r0:r1], dy[r0:r1]
            torch.mul(xs.transpose(1, 2), ds.transpose(1, 2)[..., None], out=xd)
            dys.copy_(dy_s.transpose(1, 2))  # (s, H, Q, P)
            Cs, Bs = C[r0:r1].transpose(1, 2), B[r0:r1].transpose(1, 2)
            CB = torch.matmul(Cs, Bs.transpose(-1, -2))
            E, W = _mask_and_weights(cs[r0:r1], CB, bias, E, W)
            dxd = torch.matmul(W.transpose(-1, -2), dys)  # (s, H, Q, P)
            torch.matmul(dys, xd.transpose(-1, -2), out=dW)
            W.mul_(dW)  # G = dW ∘ W
            torch.sub(W.sum(-1), W.sum(-2), out=dcs[r0:r1])
            dW.mul_(E)  # dW ∘ Lmask
            dCB = dW.view(s, G, R, Q, Q).sum(2) if R > 1 else dW
            dC[r0:r1].transpose(1, 2).copy_(torch.matmul(dCB, Bs))
            dB[r0:r1].transpose(1, 2).copy_(torch.matmul(dCB.transpose(-1, -2), Cs))
            ddelta[r0:r1].transpose(1, 2).copy_(torch.linalg.vecdot(xs.transpose(1, 2), dxd))
            out = dx[r0:r1]
            if D is None:
                torch.mul(dxd.transpose(1, 2), ds[..., None], out=out)
            else:
                torch.mul(dy_s, D, out=out).addcmul_(dxd.transpose(1, 2), ds[..., None])
                if dD is not None:
                    dD += torch.linalg.vecdot(dy_s.flatten(0, 1), xs.flatten(0, 1), dim=0)
            if dy_off is not None:
                dy_off[r0:r1].copy_(dys)
        return dx, ddelta, dcs, dB, dC, dD, dy_off


def intra_chunk(
    x: torch.Tensor,
    delta: torch.Tensor,
    cs: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    D: torch.Tensor | None = None,
    y_off: torch.Tensor | None = None,
) -> torch.Tensor:
    """SSD output of independent chunks from a zero entering state, plus ``y_off`` and D ⊙ x.

    Args:
        x: (n, Q, H, P) inputs of n chunks of length Q.
        delta: (n, Q, H) step sizes Δ.
        cs: (n, H, Q) inclusive cumulative sums of a = Δ·A within each chunk.
        B, C: (n, Q, G, N); head h reads group h // (H // G).
        D: (H, P) skip weights or ``None``.
        y_off: (n, H, Q, P) extra term (the contribution of the entering state) or ``None``.

    Returns:
        y (n, Q, H, P) = (Lmask ∘ C Bᵀ)(Δ ⊙ x) + y_off + D ⊙ x, all in x's dtype.
    """
    dt = x.dtype
    args = [t.contiguous() if t is not None else None for t in (x, delta, cs, B, C, D, y_off)]
    args = [t.to(dt) if t is not None else None for t in args]
    return IntraChunk.apply(*args)
