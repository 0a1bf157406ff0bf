"""Joint Scan ([EgoMusic] supp. Eq. 15): a shared-weight SSD over the joints of each group.

Each group token (E = P * D) is mapped to P joint tokens of width D by a Linear and a rearrange;
one mixer, shared by all G groups, scans the P joints of every group.
"""

from __future__ import annotations

import torch
from einops import rearrange
from torch import nn

from skeleton_mamba.config import MixerConfig
from skeleton_mamba.mixer import Mamba2Mixer


class JointScan(nn.Module):
    """(B, T, G, P*D) group tokens -> (B, T, G, P, D) joint tokens.

    Examples:
        >>> import torch
        >>> from skeleton_mamba import JointScan, MixerConfig
        >>> scan = JointScan(8, group_size=3, mixer=MixerConfig(headdim=8))
        >>> scan(torch.randn(2, 10, 5, 24)).shape  # (B, T, G, P * D) -> (B, T, G, P, D)
        torch.Size([2, 10, 5, 3, 8])
    """

    def __init__(self, dim: int, group_size: int, mixer: MixerConfig | None = None):
        super().__init__()
        self.group_size = group_size
        self.split = nn.Linear(group_size * dim, group_size * dim)
        self.mixer = Mamba2Mixer(dim, mixer)

    def forward(self, g: torch.Tensor, ops=None) -> torch.Tensor:
        """``ops``: replaces the projections and ``mixer.mix`` (see :meth:`GroupScan.forward`)."""
        lead = g.shape[:-1]
        if ops is None:
            y = self.mixer(rearrange(self.split(g), "... (p d) -> (...) p d", p=self.group_size))
        else:
            joints = rearrange(ops.linear(self.split, g), "... (p d) -> (...) p d", p=self.group_size)
            y = ops.linear(self.mixer.out_proj, ops.mix(self.mixer, ops.linear(self.mixer.in_proj, joints)))
        return y.reshape(*lead, self.group_size, y.shape[-1])
