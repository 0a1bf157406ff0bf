"""The blocks below the diagonal of the quadratic SSD form, with a hand-written backward.

Row block I (positions s_I ... s_I + q - 1) against all earlier positions j < s_I, per B/C group g
(its R heads side by side, R·P wide), with the anchor α_I = cs_{s_I - 1} ([Mamba-2], quadratic form):

    Y_I = u_I ⊙ (C_I B_{<I}ᵀ)(v_I ⊙ Δ_{<I} ⊙ X_{<I}),  u_I = exp(cs_I - α_I),  v_I = exp(α_I - cs_{<I}),

with cs the float64 cumulative sum of a = Δ·A over the sequence; both factors are ≤ 1, so nothing
overflows and a factor that underflows bounds a negligible entry. C_I B_{<I}ᵀ is one matrix per group,
shared by its heads, and no per-head mask is formed. Writing rhs = v ⊙ Δ ⊙ X, cb = C_I B_{<I}ᵀ and
z = cb·rhs (so Y_I = u ⊙ z), the backward per block is

    dz = u ⊙ dY_I,  d rhs = cbᵀ dz,  dcb = dz rhsᵀ,  dC_I = dcb B_{<I},  dB_{<I} = dcbᵀ C_I,
    dX_{<I} += v ⊙ Δ ⊙ d rhs,  w = Σ_p d rhs ⊙ X,  dΔ_{<I} += v ⊙ w,
    dcs_I += Σ_p dz ⊙ z,  dcs_{<I} -= Σ_p d rhs ⊙ rhs = Δ ⊙ v ⊙ w,

and the anchor's gradient dcs_{s_I - 1} += Σ (Σ_p d rhs ⊙ rhs) - Σ (Σ_p dz ⊙ z), sums over the block.
Both sums are ⟨dz, cb·rhs⟩, so it is zero in exact arithmetic, but it is kept: with it the gradient of
a_k (the cumulative sum of dcs from the end) is Σ_{j<k} Σ_p d rhs_j ⊙ rhs_j for k < s_I, the entries whose
segment holds a_k, instead of the difference of two large sums each rounded on its own; without it the
fp32 gradient of A under fast decay is several times less accurate than the recurrence's.
Autograd through the same expressions would allocate every intermediate afresh (Δ ⊙ X among them) and
copy the head-major products back; here each product is written once, in the layout the next matrix
product reads, and the sums over p reuse the buffer of d rhs.
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.precision import full_precision


def _grouped(t: torch.Tensor, G: int) -> torch.Tensor:
    """(b, s, H, P) -> (b, G, s, R, P) view, R = H // G heads of each group side by side."""
    b, s, H, P = t.shape
    return t.view(b, s, G, H // G, P).transpose(1, 2)


def _head_factor(f: torch.Tensor, G: int) -> torch.Tensor:
    """(b, s, H) per-head factors -> (b, G, s, R, 1), broadcastable against :func:`_grouped`."""
    b, s, H = f.shape
    return f.view(b, s, G, H // G, 1).transpose(1, 2)


def _per_head(t: torch.Tensor) -> torch.Tensor:
    """(b, G, s, R) -> (b, s, H), the inverse layout of :func:`_head_factor`."""
    b, G, s, R = t.shape
    return t.transpose(1, 2).reshape(b, s, G * R)


class BelowDiagonal(torch.autograd.Function):
    """See the module docstring. x (b, K·q, H, P), delta (b, K·q, H), cs (b, K·q, H) float64, B, C
    (b, K·q, G, N), all contiguous -> (b, K·q, H, P) in x's dtype, zero on the first block."""

    @staticmethod
    def forward(ctx, x, delta, cs, B, C, q):
        b, L, H, P = x.shape
        G = B.shape[2]
        R = H // G
        y = torch.empty_like(x)
        y[:, :q].zero_()
        saved = []
        for s in range(q, L, q):
            e = s + q  # L = K·q: every block is whole
            alpha = cs[:, s - 1 : s]
            v = torch.exp(alpha - cs[:, :s]).to(x.dtype)  # (b, s, H)
            u = torch.exp(cs[:, s:e] - alpha).to(x.dtype)  # (b, q, H)
            rhs = x.new_empty(b, G, s, R, P)
            torch.mul(_grouped(x[:, :s], G), _head_factor(v * delta[:, :s], G), out=rhs)
            cb = torch.matmul(C[:, s:e].transpose(1, 2), B[:, :s].permute(0, 2, 3, 1))  # (b, G, q, s)
            z = torch.matmul(cb, rhs.view(b, G, s, R * P)).view(b, G, q, R, P)
            torch.mul(z, _head_factor(u, G), out=_grouped(y[:, s:e], G))
            saved += [v, u, rhs, cb, z]
        ctx.q = q
        ctx.save_for_backward(x, delta, B, C, *saved)
        return y

    @staticmethod
    @full_precision  # backward() may be called inside an autocast region
    def backward(ctx, dy):
        x, delta, B, C, *saved = ctx.saved_tensors
        q = ctx.q
        b, L, H, P = dy.shape
        G = B.shape[2]
        R = H // G
        dx = torch.empty_like(x)
        dx[:, L - q :].zero_()  # the last block is no earlier block's column
        ddelta = delta.new_zeros(b, L, H)
        dcs = delta.new_zeros(b, L, H, dtype=torch.float64)
        dB, dC = torch.zeros_like(B), torch.zeros_like(C)
        blocks = list(enumerate(range(q, L, q)))
        for k, s in reversed(blocks):  # the longest first: it writes dx[:, :L - q] whole
            e = s + q
            v, u, rhs, cb, z = saved[5 * k : 5 * k + 5]
            dz = torch.mul(_grouped(dy[:, s:e], G), _head_factor(u, G))  # (b, G, q, R, P)
            row = _per_head(torch.linalg.vecdot(dz, z)).to(torch.float64)  # (b, q, H)
            dcs[:, s:e] += row
            dz = dz.view(b, G, q, R * P)
            drhs = torch.matmul(cb.transpose(-1, -2), dz).view(b, G, s, R, P)
            dcb = torch.matmul(dz, rhs.view(b, G, s, R * P).transpose(-1, -2))  # (b, G, q, s)
            dC[:, s:e] += torch.matmul(dcb, B[:, :s].transpose(1, 2)).transpose(1, 2)
            dB[:, :s] += torch.matmul(dcb.transpose(-1, -2), C[:, s:e].transpose(1, 2)).transpose(1, 2)
            vd = _head_factor(v * delta[:, :s], G)
            dxg = _grouped(dx[:, :s], G)
            if s == L - q:
                torch.mul(drhs, vd, out=dxg)
            else:
                dxg.addcmul_(drhs, vd)
            # w = Σ_p d rhs ⊙ X (the product in d rhs's own buffer): dΔ = v ⊙ w and Σ_p d rhs ⊙ rhs = Δ v ⊙ w
            w = _per_head(drhs.mul_(_grouped(x[:, :s], G)).sum(-1)).mul_(v)  # (b, s, H)
            ddelta[:, :s] += w
            col = (w * delta[:, :s]).to(torch.float64)
            dcs[:, :s] -= col
            dcs[:, s - 1] += col.sum(1) - row.sum(1)  # the anchor α_I = cs_{s-1}, see the module docstring
        return dx, ddelta, dcs, dB, dC, None


def below_diagonal(
    x: torch.Tensor, delta: torch.Tensor, cs: torch.Tensor, B: torch.Tensor, C: torch.Tensor, q: int
) -> torch.Tensor:
    """The contribution of earlier blocks to every block (zero for the first), see the module docstring.

    Args:
        x: (b, K·q, H, P) inputs.
        delta: (b, K·q, H) step sizes Δ.
        cs: (b, K·q, H) float64 cumulative sums of a = Δ·A over the whole sequence.
        B: (b, K·q, G, N) input projections.
        C: (b, K·q, G, N) output projections.
        q: block length.

    Returns:
        (b, K·q, H, P) in x's dtype.
    """
    t = (x, delta, cs, B, C)
    return BelowDiagonal.apply(*(v.contiguous() for v in t), q)
