"""The quadratic ("attention-like") SSD form inside chunks, with a hand-written backward.

For each chunk (reference §2 item 4, §3 step 1), per head h of B/C group g:

    Y = (Lmask ∘ C Bᵀ)(Δ ⊙ X) + Y_off + D ⊙ X,      Lmask_ij = exp(cs_i - cs_j) for i ≥ j, else 0,

with cs the inclusive cumulative sum of a = Δ·A inside the chunk and Y_off an optional term added
by the caller (the inter-chunk contribution). C·Bᵀ is formed once per group and shared by its heads.

Backward, with W = Lmask ∘ CB (per head), Xd = Δ ⊙ X and Y_in = W Xd:
    dXd = Wᵀ dY,  dW = dY Xdᵀ,  dCB = Σ_{heads of g} dW ∘ Lmask,  dC = dCB B,  dB = dCBᵀ C,
    d cs_i = Σ_j dW_ij W_ij - Σ_k dW_ki W_ki = Σ_p dY_ip Y_in,ip - Σ_p Xd_ip dXd_ip
             (∂W_ij/∂cs_i = W_ij, ∂W_ij/∂cs_j = -W_ij; the sums over Q×Q reduce to sums over P),
    dX = Δ ⊙ dXd + D ⊙ dY,  dΔ = Σ_p X ⊙ dXd,  dD = Σ X ⊙ dY,  dY_off = dY.

Speed on CPU: the work is a few large operations (every operation costs a thread fork/join, which
is expensive on a busy machine), and the Q×Q matrices Lmask and W are kept from the forward when
they fit in ``SAVE_ELEMENTS`` (a fresh 100 MB tensor costs more in page faults than the arithmetic
on it). Larger inputs are processed in tiles of at most ``SAVE_ELEMENTS`` mask entries, and the
backward then recomputes Lmask and W tile by tile, so memory stays bounded.
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.segsum import decay_mask

# Largest number of Q×Q mask entries (n·H·Q²) kept between forward and backward / held per tile.
SAVE_ELEMENTS = 1 << 25


def _tiles(n: int, per_item: int) -> list[tuple[int, int]]:
    step = max(1, SAVE_ELEMENTS // max(1, per_item))
    return [(i, min(n, i + step)) for i in range(0, n, step)]


def _mask_and_weights(cs: torch.Tensor, CB: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Lmask (s, H, Q, Q) (zero above the diagonal) and W = Lmask ∘ CB from cs (s, H, Q), CB (s, G, Q, Q)."""
    s, H, Q = cs.shape
    G = CB.shape[1]
    E = decay_mask(cs)
    W = (E.view(s, G, H // G, Q, Q) * CB[:, :, None]).view(s, H, Q, Q)
    return E, W


def _cb(B: torch.Tensor, C: torch.Tensor) -> torch.Tensor:
    """C Bᵀ per group: B, C (s, Q, G, N) -> (s, G, Q, Q)."""
    return torch.matmul(C.transpose(1, 2), B.transpose(1, 2).transpose(-1, -2))


class IntraChunk(torch.autograd.Function):
    """See the module docstring. Layouts: x (n, Q, H, P), delta (n, Q, H), cs (n, H, Q),
    B, C (n, Q, G, N), D (H, P) or None, y_off (n, Q, H, P) or None -> y (n, Q, H, P)."""

    @staticmethod
    def forward(ctx, x, delta, cs, B, C, D, y_off):
        n, Q, H, P = x.shape
        xd = x.new_empty(n, H, Q, P)
        torch.mul(x.transpose(1, 2), delta.transpose(1, 2)[..., None], out=xd)
        y_in = torch.empty_like(xd)
        tiles = _tiles(n, H * Q * Q)
        saved = []
        for r0, r1 in tiles:
            E, W = _mask_and_weights(cs[r0:r1], _cb(B[r0:r1], C[r0:r1]))
            torch.matmul(W, xd[r0:r1], out=y_in[r0:r1])
            if len(tiles) == 1:
                saved = [E, W]
        y = torch.empty_like(x)
        if y_off is None:
            y.copy_(y_in.transpose(1, 2))
        else:
            torch.add(y_in.transpose(1, 2), y_off, out=y)
        if D is not None:
            y.addcmul_(x, D)
        ctx.save_for_backward(x, delta, cs, B, C, D, xd, y_in, *saved)
        return y

    @staticmethod
    def backward(ctx, dy):
        x, delta, cs, B, C, D, xd, y_in, *saved = ctx.saved_tensors
        n, Q, H, P = x.shape
        G = B.shape[2]
        R = H // G
        dys = dy.transpose(1, 2).contiguous()  # (n, H, Q, P)
        dxd = torch.empty_like(xd)
        dB_t = B.new_empty(n, G, Q, B.shape[3])
        dC_t = torch.empty_like(dB_t)
        for r0, r1 in _tiles(n, H * Q * Q):
            s = r1 - r0
            E, W = saved if saved else _mask_and_weights(cs[r0:r1], _cb(B[r0:r1], C[r0:r1]))
            torch.matmul(W.transpose(-1, -2), dys[r0:r1], out=dxd[r0:r1])
            # W is not needed any more: dW takes its storage (a second backward through this graph
            # would then fail loudly on the version check of the saved W instead of reading it).
            dW = torch.matmul(dys[r0:r1], xd[r0:r1].transpose(-1, -2), out=W).mul_(E)  # dW ∘ Lmask
            dCB = dW.view(s, G, R, Q, Q).sum(2) if R > 1 else dW
            torch.matmul(dCB, B[r0:r1].transpose(1, 2), out=dC_t[r0:r1])
            torch.matmul(dCB.transpose(-1, -2), C[r0:r1].transpose(1, 2), out=dB_t[r0:r1])
        ddelta = torch.linalg.vecdot(x.transpose(1, 2), dxd)  # (n, H, Q)
        # Σ_p Xd dXd = Δ Σ_p X dXd = Δ·dΔ
        dcs = torch.linalg.vecdot(dys, y_in).sub_(ddelta * delta.transpose(1, 2))  # (n, H, Q)
        dx = dxd.mul_(delta.transpose(1, 2)[..., None])
        dD = None
        if D is not None:
            dx.addcmul_(dys, D[:, None, :])
            if ctx.needs_input_grad[5]:
                dD = torch.linalg.vecdot(dy.flatten(0, 1), x.flatten(0, 1), dim=0)
        dy_off = dy if ctx.needs_input_grad[6] else None
        return (dx.transpose(1, 2), ddelta.transpose(1, 2), dcs, dB_t.transpose(1, 2), dC_t.transpose(1, 2),
                dD, dy_off)


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
        y_off: (n, Q, H, P) extra term (the contribution of the entering state) or ``None``.

    Returns:
        y (n, Q, H, P) = (Lmask ∘ C Bᵀ)(Δ ⊙ x) + y_off + D ⊙ x, all in x's dtype.
    """
    dt = x.dtype
    args = [t.to(dt).contiguous() if t is not None else None for t in (x, delta, cs, B, C, D, y_off)]
    return IntraChunk.apply(*args)
