"""PFC, EDGE's Physical Foot Contact score (lower is better).

Port of Stanford-TML/EDGE ``eval/eval_pfc.py`` ([EDGE]'s metric). For FK joint positions
``(S, 24, 3)``, z-up, 30 fps (``dt = 1/30``):

1. root acceleration ``a_t = (p_(t+2) - 2 p_(t+1) + p_t) / dt^2`` of joint 0 (``S - 2`` values), its up
   component clamped at >= 0, then its norm divided by the sequence maximum;
2. horizontal displacement ``|p_(t+2) - p_(t+1)|`` of lankle, ltoes, rankle, rtoes (7, 10, 8, 11), not
   divided by ``dt``;
3. ``left_t = min(lankle, ltoes)``, ``right_t = min(rankle, rtoes)``;
4. sequence score ``mean_t(left_t * right_t * a_t)``; PFC = ``10000 x`` the mean over sequences.

A sequence whose root never accelerates (maximum 0) scores 0 (the reference divides by zero there).
Sequences are averaged deterministically (the reference samples at most 1000 files at random).
"""

from __future__ import annotations

from typing import Any

import torch
from torchmetrics import Metric

from skeleton_mamba.tasks.motion.metrics.common import Positions, as_sequences

__all__ = ["PFC", "pfc_sequence_score"]

FOOT_JOINTS = (7, 10, 8, 11)  # lankle, ltoes, rankle, rtoes (SMPL-24)


def pfc_sequence_score(positions: torch.Tensor, fps: float = 30.0, up_axis: int = 2) -> torch.Tensor:
    """Un-scaled PFC of one ``(S, 24, 3)`` sequence, ``S >= 3`` (multiply by 10000 for the paper's unit).

    Examples:
        >>> import torch
        >>> float(pfc_sequence_score(torch.zeros(30, 24, 3)))  # a still body
        0.0
        >>> _ = torch.manual_seed(0)
        >>> round(float(pfc_sequence_score(torch.randn(30, 24, 3))), 3)
        0.588
    """
    p = positions.to(torch.float64)
    dt = 1.0 / fps
    root_v = (p[1:, 0] - p[:-1, 0]) / dt  # (S-1, 3)
    root_a = (root_v[1:] - root_v[:-1]) / dt  # (S-2, 3)
    root_a[:, up_axis] = root_a[:, up_axis].clamp(min=0)
    root_a = root_a.norm(dim=-1)
    peak = root_a.max()
    if peak <= 0:
        return torch.zeros((), dtype=torch.float64)
    root_a = root_a / peak
    flat = [a for a in range(3) if a != up_axis]
    feet = p[:, list(FOOT_JOINTS)][..., flat]  # (S, 4, 2)
    foot_v = (feet[2:] - feet[1:-1]).norm(dim=-1)  # (S-2, 4)
    left = torch.minimum(foot_v[:, 0], foot_v[:, 1])
    right = torch.minimum(foot_v[:, 2], foot_v[:, 3])
    return (left * right * root_a).mean()


class PFC(Metric):
    """Physical Foot Contact score (EDGE), ``10000 x`` mean over sequences.

    Args:
        fps: frame rate (EDGE: 30).
        up_axis: vertical axis of the positions (EDGE: 2, z-up).

    ``update(positions)`` takes ``(B, S, 24, 3)`` FK joints or a list of ``(S_i, 24, 3)``.

    Examples:
        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> pfc = PFC(fps=30.0, up_axis=2)
        >>> pfc.update(torch.randn(2, 30, 24, 3))
        >>> round(float(pfc.compute()))
        5131
    """

    is_differentiable = False
    higher_is_better = False
    full_state_update = False

    def __init__(self, fps: float = 30.0, up_axis: int = 2, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if up_axis not in (0, 1, 2):
            raise ValueError(f"up_axis must be 0, 1 or 2, got {up_axis}")
        self.fps = fps
        self.up_axis = up_axis
        self.add_state("score_sum", default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("count", default=torch.tensor(0, dtype=torch.long), dist_reduce_fx="sum")

    def update(self, positions: Positions) -> None:
        for seq in as_sequences(positions, min_frames=3, joints=24):
            self.score_sum += pfc_sequence_score(seq, self.fps, self.up_axis).to(self.score_sum.device)
            self.count += 1

    def compute(self) -> torch.Tensor:
        if self.count == 0:
            raise RuntimeError("PFC.compute() called before any update()")
        return 10000.0 * self.score_sum / self.count
