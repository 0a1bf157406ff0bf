"""Input validation and the Mamba-2 discretisation of the step size Δ.

As in ``mamba_ssm/modules/mamba2.py``: Δ = clamp(softplus(dt + dt_bias), dt_limit).

Shapes (batch b, length L, heads H, head dim P, B/C groups G, state N):
x (b, L, H, P); dt (b, L, H); A (H,); B, C (b, L, G, N); D (H,) or (H, P); dt_bias (H,);
initial_state (b, H, P, N).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

# dt_limit that leaves Δ unclamped: the default of every SSD form and of MixerConfig (as mamba_ssm).
NO_DT_LIMIT: tuple[float, float] = (0.0, float("inf"))


def compute_dtype(x: torch.Tensor) -> torch.dtype:
    """fp64 stays fp64 (the test oracle); every other dtype (fp16, bf16, fp32) computes in fp32."""
    return torch.float64 if x.dtype == torch.float64 else torch.float32


def check_inputs(
    x: torch.Tensor,
    dt: torch.Tensor,
    A: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    D: torch.Tensor | None,
    dt_bias: torch.Tensor | None,
    initial_state: torch.Tensor | None,
) -> None:
    """Raise ``ValueError`` naming the offending argument when a shape breaks the SSD contract (each SSD
    form passes all eight, ``None`` for an absent optional one)."""
    if x.dim() != 4:
        raise ValueError(f"ssd: x must be (batch, length, heads, headdim), got shape {tuple(x.shape)}")
    b, L, H, P = x.shape
    if tuple(dt.shape) != (b, L, H):
        raise ValueError(f"ssd: dt must be (batch, length, heads) = {(b, L, H)}, got {tuple(dt.shape)}")
    if tuple(A.shape) != (H,):
        raise ValueError(f"ssd: A must be (heads,) = ({H},), got {tuple(A.shape)}")
    if B.dim() != 4 or B.shape[:2] != (b, L):
        raise ValueError(
            f"ssd: B must be (batch, length, groups, state) with batch, length = {b, L}, got {tuple(B.shape)}"
        )
    if tuple(C.shape) != tuple(B.shape):
        raise ValueError(f"ssd: C must have the shape of B {tuple(B.shape)}, got {tuple(C.shape)}")
    G, N = B.shape[2], B.shape[3]
    if G == 0 or H % G:
        raise ValueError(f"ssd: {H} heads cannot be split evenly over {G} B/C groups")
    if D is not None and tuple(D.shape) not in ((H,), (H, P)):
        raise ValueError(
            f"ssd: D must be (heads,) or (heads, headdim) = ({H},) or ({H}, {P}), got {tuple(D.shape)}"
        )
    if dt_bias is not None and tuple(dt_bias.shape) != (H,):
        raise ValueError(f"ssd: dt_bias must be (heads,) = ({H},), got {tuple(dt_bias.shape)}")
    if initial_state is not None and tuple(initial_state.shape) != (b, H, P, N):
        raise ValueError(
            f"ssd: initial_state must be (batch, heads, headdim, state) = {(b, H, P, N)}, "
            f"got {tuple(initial_state.shape)}"
        )


def discretize_dt(
    dt: torch.Tensor,
    dt_bias: torch.Tensor | None,
    dt_softplus: bool,
    dt_limit: tuple[float, float],
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """Δ = clamp(softplus(dt + dt_bias), dt_limit), computed in ``dtype`` (fp32 unless fp64).

    Args:
        dt: raw step (b, L, H).
        dt_bias: (H,) added before the softplus, or ``None``.
        dt_softplus: apply softplus (else Δ = dt + dt_bias).
        dt_limit: (min, max) clamp; (0, inf) leaves Δ unchanged.
        dtype: the computation dtype.

    Returns:
        Δ (b, L, H) in ``dtype``.
    """
    delta = dt.to(dtype)
    if dt_bias is not None:
        # dt + dt_bias is added in float64 and rounded once, the value of the fp32 sum, so that the
        # gradient of dt_bias, a sum over every batch entry and position, is accumulated in float64:
        # inductor's fp32 reduction of it (torch.compile) was off by 5x the fp32 recurrence's error.
        wide = torch.float64
        delta = (dt.to(wide) + dt_bias.to(wide)).to(dtype)
    if dt_softplus:
        delta = F.softplus(delta)
    lo, hi = dt_limit
    if lo > 0.0 or hi != float("inf"):
        delta = delta.clamp(min=lo, max=hi)
    return delta


def skip_matrix(D: torch.Tensor | None, H: int, P: int, dtype: torch.dtype) -> torch.Tensor | None:
    """D (H,) per head or (H, P) per channel as an (H, P) tensor of ``dtype`` (``None`` stays ``None``)."""
    if D is None:
        return None
    D = D.to(dtype)
    return D[:, None].expand(H, P) if D.dim() == 1 else D


def apply_skip(y: torch.Tensor, x: torch.Tensor, D: torch.Tensor | None) -> torch.Tensor:
    """y + D ⊙ x with D (H,) or (H, P); y, x (..., H, P), the result in y's dtype."""
    if D is None:
        return y
    return torch.addcmul(y, x.to(y.dtype), skip_matrix(D, *y.shape[-2:], y.dtype))


def sum_over_positions(a: torch.Tensor, b: torch.Tensor, scratch: torch.Tensor) -> torch.Tensor:
    """Σ a ⊙ b over chunks and positions, (n, Q, H, P) -> (H, P) in a's dtype (the gradient of D).

    ``scratch`` is a free contiguous buffer of a's size and dtype: eagerly the product goes there instead
    of a fresh allocation (whose pages would be faulted in on every call), and PyTorch's cascade
    summation keeps the sum of n·Q terms accurate. Under ``torch.compile``, which traces the hand-written
    backwards, inductor reduces sequentially (14x the recurrence's error at T = 4800), so there it is
    summed per chunk, then over the chunks in float64.
    """
    if torch.compiler.is_compiling():
        return torch.mul(a, b).sum(1).to(torch.float64).sum(0).to(a.dtype)
    return torch.mul(a, b, out=scratch.view(a.shape)).sum((0, 1))


def padded_inputs(
    x: torch.Tensor,
    dt: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    dt_bias: torch.Tensor | None,
    dt_softplus: bool,
    dt_limit: tuple[float, float],
    length: int,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """x, Δ, B, C in the compute dtype, right-padded along time to ``length`` frames.

    Δ = 0 on the padding: a padded frame adds no input and applies no decay, so the valid frames'
    outputs and the final state are unchanged.

    Returns:
        x (b, length, H, P), Δ (b, length, H), B and C (b, length, G, N).
    """
    ct = compute_dtype(x)
    delta = discretize_dt(dt, dt_bias, dt_softplus, dt_limit, ct)
    xc, Bc, Cc = x.to(ct), B.to(ct), C.to(ct)
    pad = length - x.shape[1]
    if pad:
        xc = F.pad(xc, (0, 0, 0, 0, 0, pad))
        delta = F.pad(delta, (0, 0, 0, pad))
        Bc = F.pad(Bc, (0, 0, 0, 0, 0, pad))
        Cc = F.pad(Cc, (0, 0, 0, 0, 0, pad))
    return xc, delta, Bc, Cc
