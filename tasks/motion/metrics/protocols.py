"""Named dance-evaluation protocols ``fact | bailando | edge``: which frames, which beats, which BeatAlign.

The metric formulas (kinetic / geometric features, FID, Div, both BeatAligns, PFC) are shared by the papers
and live beside this file; what differs is how their inputs are formed, and a number stands in a paper's
table only when it was computed the paper's way. Each protocol turns one ``(T, 24, 3)`` y-up SMPL-24 joint
sequence (and its music beats) into the clips the paper scores:

============  ===  ======================================  ==================================  ===============
protocol      fps  FID / Div frames                        BeatAlign                           music beats
============  ===  ======================================  ==================================  ===============
``fact``      60   generated: frames 120.. (after the      FACT form (mean over motion beats)  35-d column 34
                   seed); real: full length                from frame 120 against every beat   (AIST tempo
                                                           of the track; real: beats cut to T  prior)
``bailando``  60   first 1200 frames (real: full length),  Bailando form (mean over music      percussive HPSS
                   frame-0 root subtracted                 beats), whole sequence              beat_track
``edge``      30   5 s clips every 2.5 s (150 frames)      Bailando form per clip, against     per-slice 35-d
                                                           that slice's own beats; plus PFC    features
============  ===  ======================================  ==================================  ===============

Motion at another frame rate is resampled linearly to the protocol's (60 -> 30 takes every second frame;
30 -> 60 interpolates, as LODGE does for Bailando's metrics). The real set (FID reference and
normalisation) is the caller's: FACT's and Bailando's code use every AIST++ sequence minus the ignore list.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch

from skeleton_mamba.tasks.motion.body.resample import resample_linear
from skeleton_mamba.tasks.motion.metrics.beat_align import Variant, sequence_beat_align
from skeleton_mamba.tasks.motion.metrics.common import as_sequences
from skeleton_mamba.tasks.motion.metrics.pfc import pfc_sequence_score
from skeleton_mamba.tasks.motion.music.protocol_music import (
    bailando_beats,
    edge_slice_beats,
    edge_slice_features,
    edge_slice_starts,
    fact_beats,
)

__all__ = [
    "PROTOCOLS",
    "BailandoProtocol",
    "DanceProtocol",
    "EDGEProtocol",
    "FACTProtocol",
    "ScoredClip",
    "get_protocol",
]

Beats = np.ndarray | Sequence[int]


@dataclass
class ScoredClip:
    """One scored unit: ``joints`` (T, 24, 3) float64 as fed to FID / Div, its BeatAlign and PFC (or None)."""

    joints: torch.Tensor
    beat_align: float | None = None
    pfc: float | None = None


class DanceProtocol:
    """Base of the named protocols: ``score(joints, fps, beats, generated)`` -> the clips a paper scores.

    ``beats`` come from :meth:`music_beats` (frame indices at the protocol's fps, relative to the motion's
    first frame; for ``edge`` one array per 5 s slice) or are ``None`` (no BeatAlign).
    """

    name: ClassVar[str]
    fps: ClassVar[int]
    variant: ClassVar[Variant]
    has_pfc: ClassVar[bool] = False

    def music_beats(
        self,
        path: str | os.PathLike,
        start_s: float = 0.0,
        duration_s: float | None = None,
        cache_dir: str | os.PathLike | None = None,
    ) -> np.ndarray | list[np.ndarray]:
        """The protocol's music beats of ``path`` for a motion starting ``start_s`` seconds into the track."""
        beats = self._track_beats(path, cache_dir)
        start = int(round(start_s * self.fps))
        beats = beats[beats >= start] - start
        if duration_s is not None:
            beats = beats[beats < int(round(duration_s * self.fps))]
        return beats

    def _track_beats(self, path: str | os.PathLike, cache_dir: str | os.PathLike | None) -> np.ndarray:
        raise NotImplementedError

    def score(
        self, joints: torch.Tensor | np.ndarray, fps: float, beats=None, generated: bool = True
    ) -> list[ScoredClip]:
        """Clips of one ``(T, 24, 3)`` y-up sequence at ``fps`` under this protocol."""
        (seq,) = as_sequences([joints], min_frames=3, joints=24)
        if abs(fps - self.fps) > 1e-9:
            seq = resample_linear(seq, fps, self.fps)
        return self.clips(seq, beats, generated)

    def clips(self, joints: torch.Tensor, beats, generated: bool) -> list[ScoredClip]:
        raise NotImplementedError


class FACTProtocol(DanceProtocol):
    """[FACT] / [QEAN]: liruilong940607/mint tools/calculate_fid_scores.py, tools/calculate_beat_scores.py.

    FID / Div: generated motion from frame ``seed_frames`` (120) on (``result_motion[:, 120:]``), real
    motion in full. BeatAlign in FACT's form (mean over motion beats, ``argrelextrema(order=10)``, sigma 3):
    motion beats found on the whole generated sequence, then motion and music beats from frame 120
    (``alignment_score(audio_beats[120:], motion_beats[120:])``) with every beat of the track kept, also
    past the motion's end; real motion against the beats cut to its length. Music beats: column 34 of the
    60 fps 35-d feature (mint tools/preprocessing.py).
    """

    name = "fact"
    fps = 60
    variant = "fact"

    def __init__(self, seed_frames: int = 120) -> None:
        self.seed_frames = seed_frames

    def _track_beats(self, path, cache_dir):

        return fact_beats(path, cache_dir)

    def clips(self, joints, beats, generated):
        start = self.seed_frames if generated else 0
        if generated and len(joints) < start + 3:
            raise ValueError(f"FACT protocol: {len(joints)} frames, needs the {start}-frame seed and more")
        ba = None
        if beats is not None:
            ba = sequence_beat_align(joints, beats, "fact", self.fps, start, truncate_music=not generated)
        return [ScoredClip(joints[start:], ba)]


class BailandoProtocol(DanceProtocol):
    """[Bailando]: Bailando utils/metrics_new.py and utils/beat_align_score.py (lisiyao21/Bailando).

    FID / Div: the first ``max_frames`` (1200) generated frames (``pred_position[:1200]``) and the real
    motion in full (extract_aist_features.py), both with the frame-0 root position subtracted from every
    joint ("zero_start"). BeatAlign in Bailando's form (mean over music beats, smoothed envelope, sigma^2 = 9)
    on the whole sequence, music beats cut to the envelope length. Music beats: Bailando's own recipe from
    the HPSS-percussive onset envelope (:func:`.protocol_music.bailando_beats`).
    """

    name = "bailando"
    fps = 60
    variant = "bailando"

    def __init__(self, max_frames: int = 1200) -> None:
        self.max_frames = max_frames

    def _track_beats(self, path, cache_dir):

        return bailando_beats(path, cache_dir)

    def clips(self, joints, beats, generated):
        fid = joints[: self.max_frames] if generated else joints
        fid = fid - fid[:1, :1]
        ba = None if beats is None else sequence_beat_align(joints, beats, "bailando", self.fps)
        return [ScoredClip(fid, ba)]


class EDGEProtocol(DanceProtocol):
    """[EDGE] 5 s clips: EDGE data/slice.py, test.py, data/audio_extraction/baseline_features.py, eval_pfc.py.

    Motion is cut into 150-frame clips at 30 fps every 75 frames (5 s every 2.5 s, EDGE's test slicing).
    Which clips exist is EDGE's ``slice_motion`` rule at the motion's own rate
    (:func:`.protocol_music.edge_slice_starts`: at 60 fps, starts ``150 i`` with ``150 i + 300 <= T``),
    not the rule on the 30 fps sequence, which has ``ceil(T / 2)`` frames and one clip more for ``T = 300 +
    150 k - 1``; EDGE then takes every second frame of each 300-frame slice, as the 60 -> 30 fps
    resampling does. Clip ``i`` is paired with audio slice ``i`` (as many pairs as the shorter has), whose
    35-d features are computed on the slice alone (:func:`.protocol_music.edge_slice_features`). Per clip:
    FID / Div features, PFC (eval_pfc.py, y-up here) and BeatAlign in Bailando's form against the slice's
    beats. EDGE ships no FID, Div or BeatAlign code
    (Stanford-TML/EDGE#27, #46): BeatAlign here is Bailando's form (as LODGE and [EgoMusic]'s MM term use)
    with its 60 fps constants kept in seconds (sigma 1.5 frames, smoothing 2.5 frames at 30 fps), our choice.
    """

    name = "edge"
    fps = 30
    variant = "bailando"
    has_pfc = True
    clip_frames = 150
    stride_frames = 75

    def music_beats(self, path, start_s=0.0, duration_s=None, cache_dir=None):

        return edge_slice_beats(edge_slice_features(path, start_s, duration_s, cache_dir))

    def score(self, joints, fps, beats=None, generated=True):
        """Clips of one ``(T, 24, 3)`` y-up sequence at ``fps``: as many as EDGE slices at that rate."""

        (seq,) = as_sequences([joints], min_frames=3, joints=24)
        count = len(edge_slice_starts(len(seq), fps))
        if count == 0:
            raise ValueError(
                f"EDGE protocol: {len(seq)} frames at {fps:g} fps, a clip needs 150 frames at 30 fps (5 s)"
            )
        if abs(fps - self.fps) > 1e-9:
            seq = resample_linear(seq, fps, self.fps)
        return self.clips(seq, beats, generated, max_clips=count)

    def clips(self, joints, beats, generated, max_clips=None):
        """The clips of 30 fps ``joints``, at most ``max_clips`` (EDGE's count at the source rate)."""
        starts = range(0, len(joints) - self.clip_frames + 1, self.stride_frames)[:max_clips]
        if not starts:
            raise ValueError(f"EDGE protocol: {len(joints)} frames at 30 fps, a clip needs 150")
        if beats is not None:
            if len(beats) == 0:
                raise ValueError("EDGE protocol: no 5 s music slice to pair with the motion")
            starts = starts[: len(beats)]  # EDGE pairs motion and audio slices one to one
        out = []
        for i, s in enumerate(starts):
            clip = joints[s : s + self.clip_frames]
            ba = None if beats is None else sequence_beat_align(clip, beats[i], "bailando", self.fps)
            pfc = 10000.0 * pfc_sequence_score(clip, self.fps, up_axis=1).item()
            out.append(ScoredClip(clip, ba, pfc))
        return out


PROTOCOLS: dict[str, type[DanceProtocol]] = {
    "fact": FACTProtocol,
    "bailando": BailandoProtocol,
    "edge": EDGEProtocol,
}


def get_protocol(name: str) -> DanceProtocol:
    """The protocol called ``name`` (``fact``, ``bailando`` or ``edge``) with its published settings.

    Examples:
        >>> import torch
        >>> edge = get_protocol("edge")
        >>> edge.fps, edge.variant, edge.has_pfc
        (30, 'bailando', True)
        >>> clips = edge.score(torch.zeros(300, 24, 3), fps=30.0)  # 10 s: 5 s clips every 2.5 s
        >>> len(clips), tuple(clips[0].joints.shape)
        (3, (150, 24, 3))
    """
    if name not in PROTOCOLS:
        raise ValueError(f"unknown dance protocol {name!r}: choose one of {', '.join(PROTOCOLS)}")
    return PROTOCOLS[name]()
