"""The 72-d kinetic motion feature of AIST++ (FID_k, Div_k), vectorised in torch.

Port of google/aistplusplus_api ``aist_plusplus/features/kinetic.py`` + ``utils.py`` (also copied in
lisiyao21/Bailando ``utils/features``). For joint positions ``p`` (T, J, 3) at
``dt = 1 / fps`` and a sliding window ``w = 2``, per joint and frame ``i = 1 .. T-1``:

* windowed velocity ``v_i = sum_k (p[i+k] - p[i+k-1]) / (n dt)`` over ``k in [-w, w]`` with
  ``i+k-1 >= 0`` and ``i+k <= T-1`` (``n`` = number of valid ``k``);
* ``KE_h = sum_i |v_i,horizontal|^2 / (T-1)``, ``KE_v = sum_i v_i,up^2 / (T-1)``;
* ``EE = sum_i |mean_k a[i+k]| / (T-1)`` over ``k`` with ``i+k-1 >= 0`` and ``i+k+1 <= T-1``, where
  ``a[s] = (v2 - v1) / dt``, ``v2 = (p[s+1] - p[s]) / dt`` and ``v1 = (p[s] - p[s-1]) / dt``.

**Published quirk.** The released code computes ``v1 = p[s] - p[s-1] / dt`` (operator precedence: only the
previous position is divided by ``dt``), so EE grows with the absolute position (a static joint gets
``|59 p / dt|`` at 60 fps). Every published FID_k (FACT, Bailando, QEAN, ...) includes it, so
``published_acceleration_bug=True`` is the default to keep our numbers comparable with those tables;
``False`` gives the physically meaningful acceleration.

The output is joint-major: ``[KE_h, KE_v, EE]`` for joint 0, then joint 1, ... (``3 J`` values).
"""

from __future__ import annotations

import torch

__all__ = ["kinetic_features"]


def _window_sums(x: torch.Tensor, first: int, last: int, half_width: int, centres: torch.Tensor):
    """Sums of ``x[s]`` (time on dim -3) over ``s in [max(first, i-w), min(last, i+w)]`` per centre ``i``.

    ``x`` holds the samples ``s = first .. last`` along dim -3. Returns (sums, counts).
    """
    zero = torch.zeros_like(x[..., :1, :, :])
    csum = torch.cat([zero, x.cumsum(dim=-3)], dim=-3)  # csum[m] = sum of the first m samples
    lo = (centres - half_width).clamp(min=first) - first
    hi = (centres + half_width).clamp(max=last) - first
    sums = csum[..., hi + 1, :, :] - csum[..., lo, :, :]
    counts = (hi - lo + 1).to(x.dtype)
    return sums, counts


def kinetic_features(
    positions: torch.Tensor,
    fps: float = 60.0,
    up_axis: int = 1,
    sliding_window: int = 2,
    published_acceleration_bug: bool = True,
) -> torch.Tensor:
    """Kinetic features of joint-position sequences.

    Args:
        positions: ``(..., T, J, 3)`` joint positions in metres, ``T >= 3``.
        fps: frame rate (the AIST++ metrics use 60).
        up_axis: index of the vertical axis (1 = y-up as in AIST++, 2 = z-up).
        sliding_window: half width ``w`` of the averaging window (2 in the reference).
        published_acceleration_bug: reproduce the released code's ``v1`` precedence quirk (see module doc).

    Returns:
        ``(..., 3 J)`` float64 tensor ``[KE_h, KE_v, EE]`` per joint, joint-major.

    Examples:
        >>> import torch
        >>> kinetic_features(torch.zeros(10, 24, 3)).abs().sum().item()  # a still body: no kinetic energy
        0.0
        >>> walk = torch.zeros(10, 24, 3)
        >>> walk[..., 0] = torch.arange(10.0)[:, None] / 60  # 1 m/s along x at 60 fps
        >>> features = kinetic_features(walk)
        >>> features.shape, round(float(features[0]), 3)  # joint 0: horizontal kinetic energy first
        (torch.Size([72]), 1.0)
    """
    if positions.ndim < 3 or positions.shape[-1] != 3:
        raise ValueError(f"positions must be (..., T, J, 3), got {tuple(positions.shape)}")
    t = positions.shape[-3]
    if t < 3:
        raise ValueError(f"kinetic features need at least 3 frames, got {t}")
    if up_axis not in (0, 1, 2):
        raise ValueError(f"up_axis must be 0, 1 or 2, got {up_axis}")
    p = positions.to(torch.float64)
    dt = 1.0 / fps
    frames = torch.arange(1, t, device=p.device)  # i = 1 .. T-1

    # Velocity: samples d[s] = p[s] - p[s-1] for s = 1 .. T-1.
    d = p[..., 1:, :, :] - p[..., :-1, :, :]
    d_sum, n = _window_sums(d, 1, t - 1, sliding_window, frames)
    v = d_sum / (n[:, None, None] * dt)  # (..., T-1, J, 3)
    horizontal = [a for a in range(3) if a != up_axis]
    ke_h = v[..., horizontal].square().sum(-1).mean(-2)  # (..., J)
    ke_v = v[..., up_axis].square().mean(-2)

    # Acceleration: samples a[s] for s = 1 .. T-2.
    p_prev, p_cur, p_next = p[..., :-2, :, :], p[..., 1:-1, :, :], p[..., 2:, :, :]
    v2 = (p_next - p_cur) / dt
    v1 = p_cur - p_prev / dt if published_acceleration_bug else (p_cur - p_prev) / dt
    acc = (v2 - v1) / dt
    a_sum, m = _window_sums(acc, 1, t - 2, sliding_window, frames)
    ee = (a_sum / m[:, None, None]).norm(dim=-1).mean(-2)  # (..., J)

    return torch.stack([ke_h, ke_v, ee], dim=-1).flatten(-2)
