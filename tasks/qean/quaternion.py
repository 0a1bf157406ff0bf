"""Quaternion algebra of QEAN ([QEAN] Sec. 3.2): Hamilton product, conjugate, parameterisation.

A quaternion ``Q = e + f i + g j + h k`` is stored as the last axis ``(..., 4) = (e, f, g, h)`` (real part
first, the toolkit's ``(w, x, y, z)`` order). The Hamilton product is the standard one; [QEAN] Eq. 5
prints ``Q_h R_e`` in the **j** component, a misprint for ``Q_h R_f``, corrected here.

Quaternion parameterisation: a feature vector of ``C`` reals is read as ``C // 4`` consecutive quaternions;
the last ``C mod 4`` values do not form a complete quaternion and are dropped ([QEAN] Sec. 3.2: 35 music + 219
motion = 254 values -> 63 quaternions, "disregarding the last two dimensions").
"""

from __future__ import annotations

import torch
from einops import rearrange

__all__ = ["hamilton_product", "quaternion_conjugate", "quaternion_parameterise", "quaternion_flatten"]


def hamilton_product(q: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
    """The Hamilton product ``q (x) r`` of quaternions ``(..., 4)`` (broadcast), Eq. 5 (corrected)."""
    qe, qf, qg, qh = q.unbind(-1)
    re, rf, rg, rh = r.unbind(-1)
    return torch.stack(
        [
            qe * re - qf * rf - qg * rg - qh * rh,
            qf * re + qe * rf - qh * rg + qg * rh,
            qg * re + qh * rf + qe * rg - qf * rh,  # [QEAN] Eq. 5 prints "Q_h R_e" for "Q_h R_f"
            qh * re - qg * rf + qf * rg + qe * rh,
        ],
        dim=-1,
    )


def quaternion_conjugate(q: torch.Tensor) -> torch.Tensor:
    """``Q* = e - f i - g j - h k`` (Eq. 4) of ``(..., 4)`` quaternions."""
    return q * q.new_tensor([1.0, -1.0, -1.0, -1.0])


def quaternion_parameterise(x: torch.Tensor) -> torch.Tensor:
    """Features ``(..., C)`` -> quaternions ``(..., C // 4, 4)``; the last ``C mod 4`` values are dropped."""
    n = x.shape[-1] // 4
    if n == 0:
        raise ValueError(f"need at least 4 features to form a quaternion, got {x.shape[-1]}")
    return rearrange(x[..., : 4 * n], "... (n four) -> ... n four", four=4)


def quaternion_flatten(q: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`quaternion_parameterise` on the kept values: ``(..., n, 4)`` -> ``(..., 4 n)``."""
    if q.shape[-1] != 4:
        raise ValueError(f"expected quaternions (..., n, 4), got {tuple(q.shape)}")
    return rearrange(q, "... n four -> ... (n four)")
