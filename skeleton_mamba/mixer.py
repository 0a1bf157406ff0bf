"""The Mamba-2 mixer block in pure PyTorch, state_dict-compatible with ``mamba_ssm.Mamba2``.

in_proj -> (z, x, B, C, dt) -> causal depthwise conv over (x, B, C) + SiLU -> SSD (with D skip)
-> gated RMSNorm with z -> out_proj. Parameter names (``in_proj``, ``conv1d``, ``dt_bias``, ``A_log``,
``D``, ``norm.weight``, ``out_proj``) and the initialisation of ``A_log``, ``dt_bias`` and ``D``
follow ``mamba_ssm/modules/mamba2.py`` so weights move between the two.
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


class Mamba2Mixer(nn.Module):
    """Sequence mixer (B, L, d_model) -> (B, L, d_model), causal along L."""

    def __init__(self, d_model: int, config: MixerConfig | None = None):
        super().__init__()
        cfg = config or MixerConfig()
        self.config = cfg
        self.d_model = d_model
        self.d_inner = cfg.expand * d_model
        if self.d_inner % cfg.headdim:
            raise ValueError(
                f"d_inner {self.d_inner} (expand x d_model) must be a multiple of headdim {cfg.headdim}"
            )
        self.headdim = cfg.headdim
        self.nheads = self.d_inner // cfg.headdim
        self.ngroups = cfg.ngroups
        if self.nheads % self.ngroups:
            raise ValueError(f"{self.nheads} heads are not divisible into {self.ngroups} B/C groups")
        self.d_state = cfg.d_state
        self.chunk_size = cfg.chunk_size
        conv_dim = self.d_inner + 2 * cfg.ngroups * cfg.d_state

        # Order of the projection: [z, x, B, C, dt] (as mamba_ssm).
        self.in_proj = nn.Linear(
            d_model, 2 * self.d_inner + 2 * cfg.ngroups * cfg.d_state + self.nheads, bias=False
        )
        self.conv1d = nn.Conv1d(
            conv_dim, conv_dim, cfg.d_conv, groups=conv_dim, padding=cfg.d_conv - 1, bias=True
        )

        # dt initialisation: dt ~ exp(U(log dt_min, log dt_max)), floored; dt_bias = softplus^-1(dt).
        dt = torch.exp(
            torch.rand(self.nheads) * (math.log(cfg.dt_max) - math.log(cfg.dt_min)) + math.log(cfg.dt_min)
        )
        dt = dt.clamp(min=cfg.dt_init_floor)
        self.dt_bias = nn.Parameter(dt + torch.log(-torch.expm1(-dt)))
        lo, hi = cfg.A_init_range
        self.A_log = nn.Parameter(torch.log(torch.empty(self.nheads).uniform_(lo, hi)))
        self.D = nn.Parameter(torch.ones(self.nheads))
        for p in (self.dt_bias, self.A_log, self.D):
            p._no_weight_decay = True

        self.norm = RMSNormGated(self.d_inner, group_size=self.d_inner // cfg.ngroups, norm_before_gate=False)
        self.out_proj = nn.Linear(self.d_inner, d_model, bias=False)

    def causal_conv(self, xbc: torch.Tensor) -> torch.Tensor:
        """Causal depthwise convolution over time, (B, L, C) -> (B, L, C).

        On CUDA, ``conv1d`` (cuDNN); on CPU :func:`causal_depthwise_conv`, which avoids the slow
        depthwise ``convolution_backward`` of CPU builds. Both read ``self.conv1d``'s weights.
        """
        if xbc.is_cuda:
            return self.conv1d(xbc.transpose(1, 2))[..., : xbc.shape[1]].transpose(1, 2)
        return causal_depthwise_conv(xbc, self.conv1d.weight[:, 0], self.conv1d.bias)

    def mix(self, zxbcdt: torch.Tensor) -> torch.Tensor:
        """The mixer between its two projections: ``in_proj(u)`` (B, L, F) -> gated-normed y (B, L, d_inner).

        ``forward(u) == out_proj(mix(in_proj(u)))``. Callers whose sequence repeats tokens (the Group
        Scan reads each group token in n orders) project the distinct tokens once, gather, and average
        outputs before ``out_proj``, which is linear.
        """
        gn = self.ngroups * self.d_state
        z, xbc, dt = torch.split(zxbcdt, [self.d_inner, self.d_inner + 2 * gn, self.nheads], dim=-1)
        xbc = F.silu(self.causal_conv(xbc))
        x, b, c = torch.split(xbc, [self.d_inner, gn, gn], dim=-1)
        y = ssd(
            rearrange(x, "b l (h p) -> b l h p", p=self.headdim),
            dt,
            -torch.exp(upcast(self.A_log)),  # fp32 (fp64 stays fp64): in fp16 A could be -inf
            rearrange(b, "b l (g n) -> b l g n", g=self.ngroups),
            rearrange(c, "b l (g n) -> b l g n", g=self.ngroups),
            D=self.D,
            dt_bias=self.dt_bias,
            dt_softplus=True,
            chunk_size=self.chunk_size,
            impl="auto" if self.config.use_kernel else "torch",  # "torch": never the mamba-ssm kernel
        )
        return self.norm(rearrange(y, "b l h p -> b l (h p)"), z)

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        """u (B, L, d_model) -> (B, L, d_model)."""
        return self.out_proj(self.mix(self.in_proj(u)))
