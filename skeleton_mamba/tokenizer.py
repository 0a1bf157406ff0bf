"""Human Tokenizer and its inverse ([EgoMusic] supp. Sec. 4 and Table 1).

The tokenizer gathers the joints of each group and concatenates their features:
(B, T, J, D) -> (B, T, G, E = P * D). Groups may overlap (SMPL-24: joints 0, 3 and 9 appear three
times); the inverse scatters the P joint tokens of every group back and averages the copies of a
joint, (B, T, G, P, D) -> (B, T, J, D).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from einops import rearrange
from torch import nn


def _group_index(groups: Sequence[Sequence[int]]) -> torch.Tensor:
    sizes = {len(g) for g in groups}
    if len(sizes) != 1:
        raise ValueError(f"tokenizer groups must all have the same size, got sizes {sorted(sizes)}")
    return torch.tensor([j for g in groups for j in g], dtype=torch.long)


class HumanTokenizer(nn.Module):
    """(B, T, J, D) joint tokens -> (B, T, G, P*D) group tokens.

    Examples:
        >>> import torch
        >>> from skeleton_mamba import HumanTokenizer
        >>> x = torch.tensor([10.0, 11.0, 12.0]).view(1, 1, 3, 1)  # (B, T, J = 3, D = 1)
        >>> HumanTokenizer([[0, 1], [1, 2]])(x).flatten(0, 1)  # (B, T, G, P * D): joint 1 in both groups
        tensor([[[10., 11.],
                 [11., 12.]]])
    """

    def __init__(self, groups: Sequence[Sequence[int]]):
        super().__init__()
        self.register_buffer("index", _group_index(groups), persistent=False)
        self.num_groups = len(groups)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return rearrange(x[..., self.index, :], "... (g p) d -> ... g (p d)", g=self.num_groups)


class InverseHumanTokenizer(nn.Module):
    """(B, T, G, P, D) per-group joint tokens -> (B, T, J, D), averaging joints shared by groups.

    Examples:
        >>> import torch
        >>> from skeleton_mamba import InverseHumanTokenizer
        >>> tokens = torch.tensor([0.0, 2.0, 4.0, 6.0]).view(1, 1, 2, 2, 1)  # (B, T, G = 2, P = 2, D = 1)
        >>> InverseHumanTokenizer([[0, 1], [1, 2]], num_joints=3)(tokens).flatten()  # joint 1: mean(2, 4)
        tensor([0., 3., 6.])
    """

    def __init__(self, groups: Sequence[Sequence[int]], num_joints: int):
        super().__init__()
        index = _group_index(groups)
        joints = [j for g in groups for j in g]  # checked as numbers: no tensor is read (meta builds)
        if any(j >= num_joints or j < 0 for j in joints):
            raise ValueError(f"group joint indices must lie in [0, {num_joints})")
        counts = [joints.count(j) for j in range(num_joints)]
        missing = [j for j, count in enumerate(counts) if count == 0]
        if missing:
            raise ValueError(
                f"joints {missing} belong to no group; the inverse tokenizer cannot restore them"
            )
        self.register_buffer("index", index, persistent=False)
        self.register_buffer("inv_count", 1.0 / torch.tensor(counts, dtype=torch.float32), persistent=False)
        self.num_joints = num_joints

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        flat = rearrange(tokens, "... g p d -> ... (g p) d")
        out = flat.new_zeros(*flat.shape[:-2], self.num_joints, flat.shape[-1])
        out = out.index_add(-2, self.index, flat)
        return out * self.inv_count.to(out.dtype)[:, None]
