"""Attention layers of QEAN: self-attention with Spin Position Embedding, and Quaternion Rotary Attention.

Quaternion Rotary Attention ([QEAN] Sec. 3.4, Eqs. 25-28), per head of width ``d``:

1. ``Q = chi W^Q``, ``K = gamma W^K``, ``V = gamma W^V``.
2. P latent frequencies ``omega = ReLU(Conv1d(.))`` in ``[0, inf)`` and phases ``theta = pi tanh(Conv1d(.))``
   in ``(-pi, pi)`` per time step, from 1D convolutions over the projected queries / keys (Eq. 25).
3. Series rotation (Eq. 26): each row of ``Q`` read as quaternions ``Q~`` is right-multiplied (Hamilton
   product) by ``exp(i phi_p^Q) = cos phi + i sin phi``, ``phi_p^Q = 2 pi omega_p^Q pos^Q + theta_p^Q``, and
   each row of ``K~`` by ``exp(j phi_p^K)``; ``pos^Q = [0 .. N-1] / N``, ``pos^K = [0 .. M-1] / M``.
4. ``S = softmax(1 / (P sqrt(d)) sum_p Re[Phi_p Psi_p^H])`` (Eq. 27; the trailing "H" of the printed formula
   is read as the conjugate transpose), ``H = S V`` (Eq. 28). ``Re[q r*]`` of two quaternions is their 4-d
   dot product, so ``sum_p Re[Phi_p Psi_p^H]`` is one matrix product of the P rotated copies concatenated
   along channels.

With P = 1, omega = 0, theta = 0 the rotations are identities and QRA is canonical attention.
Deviation: a head width that is not a multiple of 4 (800 / 16 heads = 50) leaves ``d mod 4`` channels that
form no quaternion; they enter the dot product unrotated (instead of being dropped) so that the reduction to
canonical attention holds exactly. Convolution kernel size and P are not given by [QEAN] (defaults 3, 4).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from skeleton_mamba.tasks.qean.quaternion import quaternion_flatten, quaternion_parameterise
from skeleton_mamba.tasks.qean.rotary import SpinPositionEmbedding

__all__ = [
    "QuaternionRotaryAttention",
    "RotarySelfAttention",
    "quaternion_rotary_attention",
    "series_rotation",
]


def _times_unit(quats: torch.Tensor, axis: int) -> torch.Tensor:
    """``q (x) i`` (axis 1) or ``q (x) j`` (axis 2) of quaternions (..., 4): a signed permutation.

    ``(e + f i + g j + h k) i = -f + e i + h j - g k`` and ``(e + f i + g j + h k) j = -g - h i + e j + f k``.
    """
    e, f, g, h = quats.unbind(-1)
    if axis == 1:
        return torch.stack([-f, e, h, -g], dim=-1)
    if axis == 2:
        return torch.stack([-g, -h, e, f], dim=-1)
    raise ValueError(f"axis must be 1 (i) or 2 (j), got {axis}")


def series_rotation(x: torch.Tensor, phase: torch.Tensor, axis: int) -> torch.Tensor:
    """Rotate every quaternion of each row by ``exp(axis_unit * phase_p)`` for the P phases (Eq. 26).

    The Hamilton product with the unit ``cos phi + sin phi u`` (``u`` = **i** or **j**) is evaluated as
    ``x~ cos phi + (x~ (x) u) sin phi``: the same products and sums as :func:`hamilton_product` with the two
    zero components of the unit left out.

    Args:
        x: (..., T, d) rows; the first ``4 (d // 4)`` channels are read as quaternions.
        phase: (..., T, P) angles ``phi_p``.
        axis: 1 for **i** (queries), 2 for **j** (keys).

    Returns:
        (..., T, P, 4 (d // 4)) rotated quaternion channels ``x~ (x) exp(axis phi_p)``.
    """
    quats = quaternion_parameterise(x).unsqueeze(-3)  # (..., T, 1, n, 4)
    cos, sin = phase.cos()[..., None, None], phase.sin()[..., None, None]  # (..., T, P, 1, 1)
    return quaternion_flatten(quats * cos + _times_unit(quats, axis) * sin)


def quaternion_rotary_attention(
    q: torch.Tensor,
    k: torch.Tensor,
    v: torch.Tensor,
    phase_q: torch.Tensor,
    phase_k: torch.Tensor,
    dropout_p: float = 0.0,
) -> torch.Tensor:
    """QRA for one or more heads (Eqs. 26-28).

    Args:
        q: (..., N, d) queries; k: (..., M, d) keys; v: (..., M, d_v) values.
        phase_q: (..., N, P) query angles ``2 pi omega^Q pos^Q + theta^Q``; phase_k: (..., M, P) key angles.
        dropout_p: attention dropout.

    Returns:
        (..., N, d_v) ``softmax(sum_p Re[Phi_p Psi_p^H] / (P sqrt(d))) V``.
    """
    d = q.shape[-1]
    num_periods = phase_q.shape[-1]
    if phase_k.shape[-1] != num_periods:
        raise ValueError(f"queries have {num_periods} periods but keys {phase_k.shape[-1]}")
    whole = 4 * (d // 4)
    q = q * (1.0 / (num_periods * math.sqrt(d)))  # the scale, applied once to the (small) unrotated queries
    q_all = series_rotation(q, phase_q, axis=1).flatten(-2)  # (..., N, P * whole)
    k_all = series_rotation(k, phase_k, axis=2).flatten(-2)
    if whole < d:  # channels beyond whole quaternions enter each rotated copy unrotated (P times)
        q_all = torch.cat([q_all, num_periods * q[..., whole:]], dim=-1)
        k_all = torch.cat([k_all, k[..., whole:]], dim=-1)
    # sum_p Re[Phi_p Psi_p^H] is one product of the P rotated copies side by side. Written out instead of
    # scaled_dot_product_attention: the query width P * d differs from the value width, which sends SDPA
    # to its slower reference path.
    weights = torch.softmax(q_all @ k_all.transpose(-1, -2), dim=-1)
    if dropout_p > 0.0:
        weights = F.dropout(weights, dropout_p)
    return weights @ v


class RotarySelfAttention(nn.Module):
    """Multi-head self-attention with Spin Position Embedding on queries and keys.

    Args:
        dim: model width. heads: attention heads. dropout: attention dropout. base: rotary base.
    """

    def __init__(self, dim: int, heads: int, dropout: float = 0.0, base: float = 10000.0) -> None:
        super().__init__()
        if dim % heads:
            raise ValueError(f"width {dim} is not divisible by {heads} heads")
        self.heads = heads
        self.dropout = dropout
        self.qkv = nn.Linear(dim, 3 * dim)
        self.out = nn.Linear(dim, dim)
        self.rotary = SpinPositionEmbedding(dim // heads, base)

    def project(self, x: torch.Tensor, offset: int = 0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Per-token part: (B, T, dim) -> rotated q, k, v, each (B, heads, T, d), at positions offset + t.

        Attention scores depend on position differences only (Eq. 24), so tokens projected at absolute
        positions once can be attended over in any window of them (fast generation reuses them).
        """
        q, k, v = rearrange(self.qkv(x), "b t (three h d) -> three b h t d", three=3, h=self.heads)
        return self.rotary.rotate(q, offset), self.rotary.rotate(k, offset), v

    def attend(self, q: torch.Tensor, k: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """Attention over projected tokens (B, heads, T, d) -> (B, T, dim)."""
        y = F.scaled_dot_product_attention(q, k, v, dropout_p=self.dropout if self.training else 0.0)
        return self.out(rearrange(y, "b h t d -> b t (h d)"))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, T, dim) -> (B, T, dim)."""
        return self.attend(*self.project(x))


class QuaternionRotaryAttention(nn.Module):
    """Multi-head Quaternion Rotary Attention of a query series over a key-value series.

    Args:
        dim: model width (d per head = dim / heads).
        heads: attention heads.
        num_periods: P, latent frequencies and phases per time step and head.
        kernel_size: width of the frequency/phase 1D convolutions (odd).
        dropout: attention dropout.
    """

    def __init__(
        self, dim: int, heads: int, num_periods: int = 4, kernel_size: int = 3, dropout: float = 0.0
    ) -> None:
        super().__init__()
        if dim % heads:
            raise ValueError(f"width {dim} is not divisible by {heads} heads")
        if kernel_size % 2 == 0:
            raise ValueError(f"kernel_size must be odd (same-length convolution), got {kernel_size}")
        if (dim // heads) < 4:
            raise ValueError(f"head width {dim // heads} holds no quaternion (need >= 4)")
        self.heads = heads
        self.num_periods = num_periods
        self.kernel_size = kernel_size
        self.dropout = dropout
        self.q_proj = nn.Linear(dim, dim)
        self.k_proj = nn.Linear(dim, dim)
        self.v_proj = nn.Linear(dim, dim)
        self.out = nn.Linear(dim, dim)
        # Eq. 25: [omega | theta] for every head from the projected queries (keys).
        self.q_freq_phase = nn.Conv1d(dim, 2 * heads * num_periods, kernel_size, padding=kernel_size // 2)
        self.k_freq_phase = nn.Conv1d(dim, 2 * heads * num_periods, kernel_size, padding=kernel_size // 2)

    def _phases(self, x: torch.Tensor, conv: nn.Conv1d, length: int) -> torch.Tensor:
        """Angles ``2 pi omega pos + theta``: (B, T, dim) -> (B, heads, T, P); ``pos = t / length``."""
        out = conv(rearrange(x, "b t c -> b c t"))
        out = rearrange(out, "b (two h p) t -> two b h t p", two=2, h=self.heads)
        omega, theta = F.relu(out[0]), math.pi * torch.tanh(out[1])
        pos = torch.arange(x.shape[1], dtype=x.dtype, device=x.device)[:, None] / length
        return 2 * math.pi * omega * pos + theta

    def forward(
        self, x: torch.Tensor, context: torch.Tensor | None = None, num_queries: int | None = None
    ) -> torch.Tensor:
        """Attend from ``x`` (B, N, dim) over ``context`` (B, M, dim) (default: ``x``, self-attention).

        ``num_queries``: return only the first n outputs (B, n, dim); the frequency convolution still sees
        the ``kernel_size // 2`` following queries, and ``pos^Q`` keeps the full length N, so the result
        equals the first n rows of the full output.
        """
        context = x if context is None else context
        n_total = x.shape[1]
        n = n_total if num_queries is None else min(num_queries, n_total)
        x_q = x[:, : min(n_total, n + self.kernel_size // 2)]
        q = self.q_proj(x_q)
        k = self.k_proj(context)
        phase_q = self._phases(q, self.q_freq_phase, n_total)[:, :, :n]
        phase_k = self._phases(k, self.k_freq_phase, context.shape[1])
        q = rearrange(q[:, :n], "b t (h d) -> b h t d", h=self.heads)
        k = rearrange(k, "b t (h d) -> b h t d", h=self.heads)
        v = rearrange(self.v_proj(context), "b t (h d) -> b h t d", h=self.heads)
        y = quaternion_rotary_attention(q, k, v, phase_q, phase_k, self.dropout if self.training else 0.0)
        return self.out(rearrange(y, "b h t d -> b t (h d)"))
