"""Group Scan (MSSD, [EgoMusic] supp. Sec. 2, Eq. 13 and Eq. 18).

For every frame the G group tokens are read in n orders (paths). Two variants:

- ``shared=False`` (Eq. 13, the paper's MSSD): the n permuted sequences are concatenated into one
  sequence of n*G tokens and scanned by one SSD mixer; each segment is un-permuted and the n results
  are averaged. Later paths see the earlier ones, so this is not permutation-equivariant (Eq. 17).
- ``shared=True`` (Eq. 18, the frame-averaging surrogate F): each path is scanned separately with
  the same weights, un-permuted and averaged. If the path set is closed under a group permutation
  rho ({rho pi_i} = {pi_i}), then F(g^rho) = F(g)^rho (Eq. 20).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from einops import rearrange
from torch import nn

from skeleton_mamba.config import MixerConfig
from skeleton_mamba.mixer import Mamba2Mixer


class GroupScan(nn.Module):
    """(B, T, G, E) group tokens -> (B, T, G, E).

    Examples:
        >>> import torch
        >>> from skeleton_mamba import GroupScan, MixerConfig
        >>> scan = GroupScan(16, paths=[[0, 1, 2], [2, 1, 0]], mixer=MixerConfig(headdim=8))  # 2 scan orders
        >>> scan(torch.randn(2, 10, 3, 16)).shape  # (B, T, G, E)
        torch.Size([2, 10, 3, 16])
    """

    def __init__(
        self,
        dim: int,
        paths: Sequence[Sequence[int]],
        shared: bool = False,
        mixer: MixerConfig | None = None,
    ):
        super().__init__()
        lists = [[int(g) for g in p] for p in paths]  # checked as numbers: no tensor is read (meta builds)
        num_groups = len(lists[0]) if lists else 0
        for p in lists:
            if sorted(p) != list(range(num_groups)):
                raise ValueError(f"group path {p} is not a permutation of 0..{num_groups - 1}")
        paths_t = torch.tensor(lists, dtype=torch.long)
        self.num_paths, self.num_groups = paths_t.shape
        self.shared = shared
        # Gather index of the concatenated permuted sequence, and the (G, n*G) matrix that
        # un-permutes every path and averages the n results: position k of path i holds group
        # paths[i][k].
        self.register_buffer("path_index", paths_t.flatten(), persistent=False)
        unpermute = torch.zeros(self.num_groups, self.num_paths * self.num_groups)
        unpermute[paths_t.flatten(), torch.arange(unpermute.shape[1])] = 1.0 / self.num_paths
        self.register_buffer("unpermute_mean", unpermute, persistent=False)
        self.mixer = Mamba2Mixer(dim, mixer)

    @property
    def path_elements(self) -> int:
        """Elements per frame of the widest intermediate, the projected n*G-token path sequence."""
        return self.num_paths * self.num_groups * self.mixer.d_in_proj

    def forward(self, g: torch.Tensor, ops=None) -> torch.Tensor:
        """Same result as scanning ``mixer(g[:, path_index])``, at 1/n of the projection cost.

        The mixer's ``in_proj`` and ``out_proj`` act per token and are linear, so the n*G-token
        sequence's projections are computed on the G distinct group tokens and gathered, and the n
        path outputs are averaged before ``out_proj`` (mean and a linear map commute). Only the
        causal conv, the SSD and the gated norm see the full n*G-token sequence. ``ops`` (the frame-by-frame
        path passes :class:`~skeleton_mamba.runtime.frame_ops.FrameOps`) replaces the projections by
        ``ops.linear(layer, x)`` and ``mixer.mix`` by ``ops.mix(mixer, zxbcdt)``.
        """
        mixer = self.mixer
        mix = type(mixer).mix if ops is None else ops.mix
        project = nn.Linear.__call__ if ops is None else ops.linear
        lead = g.shape[:-2]
        g = g.reshape(-1, self.num_groups, g.shape[-1])  # (BT, G, E)
        # (BT, n*G, F): the projections of the n permuted group sequences, concatenated.
        seq = torch.index_select(project(mixer.in_proj, g), 1, self.path_index)
        if self.shared:
            y = mix(mixer, rearrange(seq, "b (n g) f -> (b n) g f", n=self.num_paths))
            y = rearrange(y, "(b n) g d -> b (n g) d", n=self.num_paths)
        else:
            y = mix(mixer, seq)
        # (G, n*G) @ (BT, n*G, d): un-permute each path and average over paths.
        y = project(mixer.out_proj, torch.matmul(self.unpermute_mean.to(y.dtype), y))
        return y.reshape(*lead, self.num_groups, y.shape[-1])
