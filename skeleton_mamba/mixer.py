"""The Mamba-2 mixer block in pure PyTorch, state_dict-compatible with ``mamba_ssm.Mamba2``.

in_proj -> (z0, x0, z, x, B, C, dt) -> causal depthwise conv over (x, B, C) + SiLU -> SSD (with D skip)
-> gated RMSNorm with z -> [silu(z0) * x0 | y] -> out_proj ([Mamba-2]; z0, x0 are empty unless
``d_ssm < d_inner``). Parameter names (``in_proj``, ``conv1d``, ``dt_bias``, ``A_log``, ``D``,
``norm.weight``, ``out_proj``), the options of :class:`~skeleton_mamba.config.MixerConfig` and the
initialisation of ``A_log``, ``dt_bias`` and ``D`` follow ``mamba_ssm/modules/mamba2.py`` so weights move
between the two.

The mixer owns its math in every form: :meth:`Mamba2Mixer.forward` / :meth:`~Mamba2Mixer.mix` for a
sequence, :meth:`~Mamba2Mixer.step` for one token with the states of
:meth:`~Mamba2Mixer.allocate_inference_cache` (as ``mamba_ssm.Mamba2``), and the pieces every form shares
(:meth:`~Mamba2Mixer.split`, :meth:`~Mamba2Mixer.split_xbc`, :meth:`~Mamba2Mixer.skip`,
:meth:`~Mamba2Mixer.output`), which the frame path (:func:`skeleton_mamba.runtime.frame_ops.short_mix`) uses
too. The one-token recurrence ([Mamba-2] SSD):

    h_t = exp(Δ_t A) h_{t-1} + (Δ_t x_t) ⊗ B_t,   y_t = h_t C_t + D ⊙ x_t
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from skeleton_mamba.causal_conv import causal_depthwise_conv
from skeleton_mamba.config import MixerConfig
from skeleton_mamba.norm import RMSNormGated, upcast
from skeleton_mamba.ssd import ssd
from skeleton_mamba.ssd.discretize import apply_skip, compute_dtype, discretize_dt
from skeleton_mamba.ssd.precision import outside_autocast
from skeleton_mamba.ssd.recurrence import recurrence_step


class Mamba2Mixer(nn.Module):
    """Sequence mixer (B, L, d_model) -> (B, L, d_model), causal along L.

    Examples:
        >>> import torch
        >>> from skeleton_mamba import Mamba2Mixer, MixerConfig
        >>> mixer = Mamba2Mixer(16, MixerConfig(d_state=8, headdim=8))
        >>> u = torch.randn(1, 20, 16)
        >>> mixer(u).shape  # (B, L, d_model) -> (B, L, d_model)
        torch.Size([1, 20, 16])
        >>> v = u.clone()
        >>> v[:, 10:] += 1.0  # change the future only
        >>> torch.allclose(mixer(u)[:, :10], mixer(v)[:, :10])  # a causal scan: the past is unchanged
        True
    """

    def __init__(self, d_model: int, config: MixerConfig | None = None):
        super().__init__()
        cfg = config or MixerConfig()
        self.config = cfg
        self.d_model = d_model
        self.d_inner = cfg.expand * d_model
        self.d_ssm = self.d_inner if cfg.d_ssm is None else cfg.d_ssm
        self.d_mlp = self.d_inner - self.d_ssm  # gated-MLP channels beside the SSM
        self.headdim = cfg.headdim
        self.ngroups = cfg.ngroups
        self.dt_limit = _check_options(cfg, self.d_inner, self.d_ssm)
        self.nheads = self.d_ssm // cfg.headdim
        self.d_state = cfg.d_state
        self.chunk_size = cfg.chunk_size
        self.conv_dim = conv_dim = self.d_ssm + 2 * cfg.ngroups * cfg.d_state

        # Order of the projection: [z0, x0, z, x, B, C, dt] (as mamba_ssm; z0, x0 only when d_ssm < d_inner).
        self.d_in_proj = 2 * self.d_inner + 2 * cfg.ngroups * cfg.d_state + self.nheads
        self.in_proj = nn.Linear(d_model, self.d_in_proj, bias=cfg.bias)
        self.conv1d = nn.Conv1d(
            conv_dim, conv_dim, cfg.d_conv, groups=conv_dim, padding=cfg.d_conv - 1, bias=cfg.conv_bias
        )

        # dt initialisation: dt ~ exp(U(log dt_min, log dt_max)), floored; dt_bias = softplus^-1(dt).
        dt = torch.exp(
            torch.rand(self.nheads) * (math.log(cfg.dt_max) - math.log(cfg.dt_min)) + math.log(cfg.dt_min)
        )
        dt = dt.clamp(min=cfg.dt_init_floor)
        self.dt_bias = nn.Parameter(dt + torch.log(-torch.expm1(-dt)))
        lo, hi = cfg.A_init_range
        self.A_log = nn.Parameter(torch.log(torch.empty(self.nheads).uniform_(lo, hi)))
        self.D = nn.Parameter(torch.ones(self.d_ssm if cfg.D_has_hdim else self.nheads))
        for p in (self.dt_bias, self.A_log, self.D):
            p._no_weight_decay = True

        if cfg.rmsnorm:
            self.norm = RMSNormGated(
                self.d_ssm, group_size=self.d_ssm // cfg.ngroups, norm_before_gate=cfg.norm_before_gate
            )
        self.out_proj = nn.Linear(self.d_inner, d_model, bias=cfg.bias)

    def causal_conv(self, xbc: torch.Tensor) -> torch.Tensor:
        """Causal depthwise convolution over time, (B, L, C) -> (B, L, C).

        On CUDA and under ``torch.export``, ``conv1d`` (cuDNN; one operator for any length); on CPU
        :func:`causal_depthwise_conv`, which avoids the slow depthwise ``convolution_backward`` of CPU
        builds. Both read ``self.conv1d``'s weights.
        """
        if xbc.is_cuda or torch.compiler.is_exporting():
            return self.conv1d(xbc.transpose(1, 2))[..., : xbc.shape[1]].transpose(1, 2)
        return causal_depthwise_conv(xbc, self.conv1d.weight[:, 0], self.conv1d.bias)

    def skip_weight(self) -> torch.Tensor:
        """D as the SSD takes it: (H,) per head, or (H, P) per channel with ``D_has_hdim``."""
        if self.config.D_has_hdim:
            return rearrange(self.D, "(h p) -> h p", p=self.headdim)
        return self.D

    def gate(self, y: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """The SSM output gated by z, (B, L, d_ssm): gated RMSNorm, or ``y * silu(z)`` without ``rmsnorm``."""
        if self.config.rmsnorm:
            return self.norm(y, z)
        return y * F.silu(z)

    def split(self, zxbcdt: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """``in_proj``'s output (..., F) -> z0, x0 (..., d_mlp), z (..., d_ssm), xBC (..., conv_dim),
        dt (..., H), in ``mamba_ssm.Mamba2``'s order."""
        gn = self.ngroups * self.d_state
        sizes = [self.d_mlp, self.d_mlp, self.d_ssm, self.d_ssm + 2 * gn, self.nheads]
        return torch.split(zxbcdt, sizes, dim=-1)

    def split_xbc(self, xbc: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The convolved xBC (..., conv_dim) -> x (..., d_ssm), B and C (..., ngroups·d_state)."""
        gn = self.ngroups * self.d_state
        return torch.split(xbc, [self.d_ssm, gn, gn], dim=-1)

    def skip(self, y: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """y + D ⊙ x for y, x (..., H, P), in y's dtype (the sequence form's SSD adds it itself)."""
        return apply_skip(y, x, self.skip_weight())

    def output(self, y: torch.Tensor, z: torch.Tensor, z0: torch.Tensor, x0: torch.Tensor) -> torch.Tensor:
        """The SSM output y (..., d_ssm) gated by z, after the gated-MLP channels silu(z0)·x0 when
        d_ssm < d_inner: (..., d_inner), the input of ``out_proj``."""
        y = self.gate(y, z)
        if self.d_mlp:
            y = torch.cat([F.silu(z0) * x0, y], dim=-1)
        return y

    def mix(self, zxbcdt: torch.Tensor) -> torch.Tensor:
        """The mixer between its two projections: ``in_proj(u)`` (B, L, F) -> gated y (B, L, d_inner).

        ``forward(u) == out_proj(mix(in_proj(u)))``. Callers whose sequence repeats tokens (the Group
        Scan reads each group token in n orders) project the distinct tokens once, gather, and average
        outputs before ``out_proj``, which is linear.
        """
        z0, x0, z, xbc, dt = self.split(zxbcdt)
        x, b, c = self.split_xbc(F.silu(self.causal_conv(xbc)))
        y = ssd(
            rearrange(x, "b l (h p) -> b l h p", p=self.headdim),
            dt,
            -torch.exp(upcast(self.A_log)),  # fp32 (fp64 stays fp64): in fp16 A could be -inf
            rearrange(b, "b l (g n) -> b l g n", g=self.ngroups),
            rearrange(c, "b l (g n) -> b l g n", g=self.ngroups),
            D=self.skip_weight(),
            dt_bias=self.dt_bias,
            dt_softplus=True,
            dt_limit=self.dt_limit,
            chunk_size=self.chunk_size,
            impl="auto" if self.config.use_kernel else "torch",  # "torch": never the mamba-ssm kernel
        )
        return self.output(rearrange(y, "b l h p -> b l (h p)"), z, z0, x0)

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        """u (B, L, d_model) -> (B, L, d_model)."""
        return self.out_proj(self.mix(self.in_proj(u)))

    def allocate_inference_cache(
        self,
        batch_size: int,
        max_seqlen: int | None = None,
        dtype: torch.dtype | None = None,
        device: torch.device | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Zero states for :meth:`step`, as ``mamba_ssm.Mamba2.allocate_inference_cache``.

        Returns:
            conv_state (batch, conv_dim, d_conv) in ``dtype`` (default: the weights'), the last inputs of
            the convolution; ssm_state (batch, nheads, headdim, d_state) in the SSD's compute dtype (fp32,
            fp64 for fp64). ``max_seqlen`` is accepted for mamba_ssm's signature; the size is fixed.
        """
        weight = self.conv1d.weight
        dtype = dtype or weight.dtype
        device = device or weight.device
        conv = torch.zeros(batch_size, self.conv_dim, self.config.d_conv, dtype=dtype, device=device)
        ssm_dtype = compute_dtype(torch.empty(0, dtype=dtype))
        ssm = torch.zeros(batch_size, self.nheads, self.headdim, self.d_state, dtype=ssm_dtype, device=device)
        return conv, ssm

    def step(self, u: torch.Tensor, conv_state: torch.Tensor, ssm_state: torch.Tensor) -> torch.Tensor:
        """One token: u (B, d_model) -> (B, d_model); both states updated in place.

        Equal to the last output of ``forward(cat(previous tokens, u))``, as ``mamba_ssm.Mamba2.step``
        (which takes (B, 1, d_model) and also returns the states), with ``dt_limit`` applied as in the
        sequence form (mamba_ssm's own step skips it).
        """
        b = u.shape[0]
        h, p, n, g = self.nheads, self.headdim, self.d_state, self.ngroups
        z0, x0, z, xbc, dt = self.split(self.in_proj(u))
        # Causal depthwise convolution over the last d_conv inputs (shift the window left, append).
        window = torch.cat([conv_state[..., 1:], xbc[..., None]], dim=-1)
        conv_state.copy_(window)
        xbc = (window * self.conv1d.weight[:, 0]).sum(-1)  # (B, conv_dim)
        if self.conv1d.bias is not None:
            xbc = xbc + self.conv1d.bias
        x, B, C = self.split_xbc(F.silu(xbc))
        ct = ssm_state.dtype
        with outside_autocast(ssm_state):  # Δ, the decay, the state and y = h C in ct (fp32) under autocast
            delta = discretize_dt(dt, self.dt_bias, True, self.dt_limit, ct)  # (B, H)
            xh = x.to(ct).view(b, h, p)
            decay = torch.exp(delta * -torch.exp(self.A_log.to(ct)))  # exp(Δ A), (B, H)
            xd = xh * delta[:, :, None]  # Δ x, (B, H, P)
            Bg, Cg = B.to(ct).view(b, g, n), C.to(ct).view(b, g, n)
            if torch.compiler.is_compiling():
                y = _state_update_pointwise(ssm_state, decay, xd, Bg, Cg)
            else:
                _, y = recurrence_step(ssm_state, decay, xd, Bg, Cg, out=ssm_state)
            y = self.skip(y, xh)
        return self.out_proj(self.output(y.to(u.dtype).view(b, self.d_ssm), z, z0, x0))


def _state_update_pointwise(
    ssm_state: torch.Tensor, decay: torch.Tensor, xd: torch.Tensor, B: torch.Tensor, C: torch.Tensor
) -> torch.Tensor:
    """Compiled twin of :func:`~skeleton_mamba.ssd.recurrence.recurrence_step` (kept: a second copy of
    the step): h <- exp(Δ A) h + (Δ x) ⊗ B in place and y = h C, as element-wise work and a reduction.

    The form of :meth:`Mamba2Mixer.step` in compiled code
    (:class:`~skeleton_mamba.runtime.compiling.CompiledStep`): inductor computes the new state directly into
    ``ssm_state``'s storage (no matrix product whose result is copied back).
    ``tests/backbone/test_streaming.py`` runs both forms and checks they equal the sequence mixer. ssm_state
    (B, H, P, N), decay (B, H), xd (B, H, P), B and C (B, G, N) -> y (B, H, P).
    """
    b, h, p, n = ssm_state.shape
    g = B.shape[1]
    r = h // g
    new = (ssm_state * decay[:, :, None, None]).view(b, g, r, p, n)
    new = new + xd.view(b, g, r, p, 1) * B.view(b, g, 1, 1, n)
    ssm_state.copy_(new.view(b, h, p, n))
    return (new * C.view(b, g, 1, 1, n)).sum(-1).view(b, h, p)


def _check_options(cfg: MixerConfig, d_inner: int, d_ssm: int) -> tuple[float, float]:
    """Reject option values ``mamba_ssm.Mamba2`` would not accept; returns ``dt_limit`` as a float pair."""
    if not 0 < d_ssm <= d_inner:
        raise ValueError(f"d_ssm {d_ssm} must lie in (0, d_inner = expand x d_model = {d_inner}]")
    if d_ssm % cfg.headdim:
        raise ValueError(f"d_ssm {d_ssm} (default d_inner) must be a multiple of headdim {cfg.headdim}")
    if (d_ssm // cfg.headdim) % cfg.ngroups:
        raise ValueError(f"{d_ssm // cfg.headdim} heads are not divisible into {cfg.ngroups} B/C groups")
    try:
        lo, hi = (float(v) for v in cfg.dt_limit)
    except (TypeError, ValueError) as err:
        raise ValueError(f"dt_limit must be a pair (min, max), got {cfg.dt_limit!r}") from err
    if not (0.0 <= lo < hi):
        raise ValueError(f"dt_limit {cfg.dt_limit!r} must satisfy 0 <= min < max (max may be inf)")
    if cfg.norm_before_gate and not cfg.rmsnorm:
        raise ValueError("norm_before_gate=True needs rmsnorm=True (there is no norm to put before the gate)")
    return lo, hi
