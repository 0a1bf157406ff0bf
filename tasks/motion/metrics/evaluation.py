"""A dance evaluation under one named protocol: FID_k / FID_g, Div_k / Div_g, BeatAlign (and PFC for EDGE).

Used by QEAN's and EMM's test loops and by ``sm evaluate-dance``. Sequences go in through
:meth:`DanceEvaluation.add`, which applies the protocol (:mod:`.protocols`: slicing, root handling, music
beats, BeatAlign form); the metrics are torchmetrics objects (``"cat"`` / ``"sum"`` states), so values are
exact over processes.
"""

from __future__ import annotations

import torch
from torch import nn
from torchmetrics import MeanMetric

from skeleton_mamba.tasks.motion.metrics.fid import (
    FrechetMotionDistance,
    MotionDiversity,
    average_pairwise_distance,
)
from skeleton_mamba.tasks.motion.metrics.protocols import DanceProtocol, ScoredClip, get_protocol

__all__ = ["DanceEvaluation"]


def _mean() -> MeanMetric:
    metric = MeanMetric()
    metric.set_dtype(torch.float64)
    return metric


class DanceEvaluation(nn.Module):
    """Accumulates a real (reference) and a generated set under ``protocol``; :meth:`compute` gives the row.

    Args:
        protocol: ``"fact"``, ``"bailando"``, ``"edge"`` or a :class:`.protocols.DanceProtocol`.

    ``compute()`` returns ``FID_k, FID_g, Div_k, Div_g`` (generated set normalised by the real statistics;
    present when each set has at least 2 clips),
    ``Div_k_real, Div_g_real`` (the real set's own diversity, the ground-truth row), ``BeatAlign`` and
    ``BeatAlign_real`` (when beats were given), ``PFC`` (EDGE), and the clip counts.

    Examples:
        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> evaluation = DanceEvaluation("edge")
        >>> for _ in range(2):  # two 10 s motions each side, three 5 s clips each
        ...     _ = evaluation.add(torch.randn(300, 24, 3), fps=30.0, real=True)
        ...     _ = evaluation.add(0.5 * torch.randn(300, 24, 3), fps=30.0)
        >>> row = evaluation.compute()
        >>> row["generated_clips"], row["real_clips"], sorted(k for k in row if k.startswith("FID"))
        (6, 6, ['FID_g', 'FID_k'])
    """

    def __init__(self, protocol: str | DanceProtocol = "fact") -> None:
        super().__init__()
        self.protocol = get_protocol(protocol) if isinstance(protocol, str) else protocol
        fps = self.protocol.fps
        self.fid = nn.ModuleDict({k: FrechetMotionDistance(k, fps, reset_real_features=False)
                                  for k in ("kinetic", "geometric")})  # fmt: skip
        self.div = nn.ModuleDict({k: MotionDiversity(k, fps, reset_real_features=False)
                                  for k in ("kinetic", "geometric")})  # fmt: skip
        self.beat_align = nn.ModuleDict({"generated": _mean(), "real": _mean()})
        self.pfc = _mean()
        self.counts = {"generated": 0, "real": 0}

    def add(self, joints, fps: float, beats=None, real: bool = False) -> list[ScoredClip]:
        """Score one ``(T, 24, 3)`` y-up sequence at ``fps`` (beats from ``protocol.music_beats`` or None)."""
        clips = self.protocol.score(joints, fps, beats, generated=not real)
        side = "real" if real else "generated"
        positions = [c.joints for c in clips]
        for metric in (*self.fid.values(), *self.div.values()):
            metric.update(positions, real=real)
        for clip in clips:
            if clip.beat_align is not None:
                self.beat_align[side].update(clip.beat_align)
            if clip.pfc is not None and not real:
                self.pfc.update(clip.pfc)
        self.counts[side] += len(clips)
        return clips

    def compute(self) -> dict[str, float]:
        """The metrics; FID and Div only when each set holds at least 2 clips (in this process)."""
        out: dict[str, float] = {}
        if min(self.counts.values()) >= 2:
            out["FID_k"] = self.fid["kinetic"].compute().item()
            out["FID_g"] = self.fid["geometric"].compute().item()
            out["Div_k"] = self.div["kinetic"].compute().item()
            out["Div_g"] = self.div["geometric"].compute().item()
            real_k, _ = self.div["kinetic"]._normalised_sets()
            real_g, _ = self.div["geometric"]._normalised_sets()
            out["Div_k_real"] = average_pairwise_distance(real_k).item()
            out["Div_g_real"] = average_pairwise_distance(real_g).item()
        for side, key in (("generated", "BeatAlign"), ("real", "BeatAlign_real")):
            if self.beat_align[side].update_count:
                out[key] = self.beat_align[side].compute().item()
        if self.pfc.update_count:
            out["PFC"] = self.pfc.compute().item()
        out["generated_clips"] = self.counts["generated"]
        out["real_clips"] = self.counts["real"]
        return out

    def reset(self, keep_real: bool = True) -> None:
        """Forget the generated set (and the real one unless ``keep_real``)."""
        for metric in (*self.fid.values(), *self.div.values()):
            metric.reset()
            if not keep_real:
                metric.real_features = []
        self.beat_align["generated"].reset()
        self.pfc.reset()
        self.counts["generated"] = 0
        if not keep_real:
            self.beat_align["real"].reset()
            self.counts["real"] = 0
