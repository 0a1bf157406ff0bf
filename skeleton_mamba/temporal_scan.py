"""Temporal Scan: a bidirectional SSD along time for every joint ([EgoMusic] supp. Table 1).

Independent forward and backward mixers, summed and projected by a Linear. Variable-length batches
are right-padded; the backward direction reverses only the valid prefix of each sequence, so it
starts at the last valid frame and padded frames (which stay at the end in both directions) can
never reach a valid frame through the causal scans. On a CPU the joint sequences go through in
slices of at most ``slice_elements`` projected elements (``skeleton_mamba.runtime.slicing``).

``causal=True`` keeps only the forward mixer (frame t sees frames <= t), the form that also runs
frame by frame (``skeleton_mamba.runtime.streaming``).
"""

from __future__ import annotations

import torch
from einops import rearrange
from torch import nn

from skeleton_mamba.config import MixerConfig
from skeleton_mamba.mixer import Mamba2Mixer
from skeleton_mamba.padding import zero_padding
from skeleton_mamba.runtime.slicing import map_slices, slice_length


def valid_prefix_reversal(mask: torch.Tensor) -> torch.Tensor:
    """Time index that reverses each valid prefix and leaves the padding in place.

    Args:
        mask: (B, T) bool, True on valid frames; valid frames must form a prefix.

    Returns:
        (B, T) long index ``r`` with ``r[b, t] = len_b - 1 - t`` for ``t < len_b`` else ``t``
        (an involution: applying it twice is the identity).
    """
    lengths = mask.sum(dim=1, keepdim=True)
    t = torch.arange(mask.shape[1], device=mask.device)[None]
    return torch.where(t < lengths, lengths - 1 - t, t)


def check_prefix_mask(mask: torch.Tensor) -> None:
    """Raise if a padding mask is not a valid prefix (True...True False...False) per row.

    Under ``torch.export`` only the dtype and rank are checked (a value check has no place in a graph):
    an exported model trusts its mask to be a prefix.
    """
    if mask.dtype != torch.bool or mask.dim() != 2:
        raise ValueError(f"padding mask must be a (B, T) bool tensor, got {tuple(mask.shape)} {mask.dtype}")
    if not torch.compiler.is_exporting() and bool((mask[:, 1:] & ~mask[:, :-1]).any()):
        raise ValueError("padding mask must mark a valid prefix of each sequence (right padding only)")


class TemporalScan(nn.Module):
    """(B, T, J, D) -> (B, T, J, D), each joint scanned along T in both directions.

    Examples:
        >>> import torch
        >>> from skeleton_mamba import MixerConfig, TemporalScan
        >>> scan = TemporalScan(16, MixerConfig(headdim=8), causal=True)  # forward only, for streaming
        >>> x = torch.randn(1, 20, 2, 16)  # (B, T, J, D)
        >>> y = x.clone()
        >>> y[:, 10:] += 1.0
        >>> torch.allclose(scan(x)[:, :10], scan(y)[:, :10])  # frame t sees frames <= t only
        True
    """

    def __init__(
        self,
        dim: int,
        mixer: MixerConfig | None = None,
        slice_elements: int | None = None,
        causal: bool = False,
    ):
        super().__init__()
        self.causal = causal
        self.forward_mixer = Mamba2Mixer(dim, mixer)
        self.backward_mixer = None if causal else Mamba2Mixer(dim, mixer)
        self.proj = nn.Linear(dim, dim)
        self.slice_elements = slice_elements

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        num_joints = x.shape[2]
        if mask is None:
            mask = torch.ones(x.shape[:2], dtype=torch.bool, device=x.device)
        else:
            x = zero_padding(x, mask)  # padded values never enter the scans (matrix forms spread them back)
        seq = rearrange(x, "b t j d -> (b j) t d")
        index = valid_prefix_reversal(mask).repeat_interleave(num_joints, dim=0)
        per_sequence = seq.shape[1] * self.forward_mixer.d_in_proj
        length = slice_length(seq, 0, per_sequence, self.slice_elements)
        y = map_slices(self.scan, 0, length, seq, index)
        return rearrange(y, "(b j) t d -> b t j d", j=num_joints)

    def scan(self, seq: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        """Both directions over sequences (L, T, D); ``index`` (L, T) reverses each valid prefix."""
        fwd = self.forward_mixer(seq)
        if self.backward_mixer is None:
            return self.proj(fwd)
        index = index[..., None].expand_as(seq)
        bwd = torch.gather(self.backward_mixer(torch.gather(seq, 1, index)), 1, index)
        return self.proj(fwd + bwd)
