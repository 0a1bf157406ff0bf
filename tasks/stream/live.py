"""The live dance loop: audio chunks in, one pose per 30 fps frame out, as soon as its audio is there.

For every chunk: causal features of the frames it completes (:class:`~.features.CausalMusicFeatures`),
then one :meth:`StreamDancer.step` per frame, fed its own previous pose. The latency of frame t is
the wall time from the delivery of the chunk that completed frame t's audio to its pose (feature
extraction and the network step); the frame's own audio (33.3 ms, :mod:`.features`) and the chunk
size come on top of it and are reported beside it.

The network's state is fixed in size; the dance itself (written at the end) is kept, 1.3 kB per frame
(pose tokens and features: about 24 MB for ten minutes).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from skeleton_mamba.runtime.compiling import compile_step_or_eager
from skeleton_mamba.tasks.stream.features import CausalMusicFeatures, beat_phase_for
from skeleton_mamba.tasks.stream.model import POSE_CHANNELS, StreamDancer

__all__ = ["LiveDancer"]


@dataclass
class LiveDancer:
    """Dance to audio pushed chunk by chunk with a trained :class:`StreamDancer`.

    Args:
        model: the network (put in eval mode here).
        sample_rate: rate of the pushed audio.
        compile: step the backbone through ``torch.compile`` (:mod:`skeleton_mamba.runtime.compiling`),
            compiled here (about a minute at the paper width); if compiling fails, a warning and the
            eager step. ``compile_seconds`` is the compile time (None: eager).
    """

    model: StreamDancer
    sample_rate: int
    compile: bool = False
    poses: list[torch.Tensor] = field(default_factory=list)
    music: list[np.ndarray] = field(default_factory=list)
    latency_ms: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.model.eval()
        self.backbone_step, self.compile_seconds = self.model.backbone.step, None
        if self.compile:
            self.backbone_step, self.compile_seconds = compile_step_or_eager(self.model.backbone)
        self.beat_phase = beat_phase_for(self.model.music_dim)  # the features it was trained on
        self.features = CausalMusicFeatures(self.sample_rate, self.beat_phase)
        self.state = self.model.init_state(1)
        weight = next(self.model.parameters())
        self.prev = torch.zeros(1, 24, POSE_CHANNELS, dtype=weight.dtype, device=weight.device)
        self._warm_up()

    def _warm_up(self) -> None:
        """One throwaway frame (librosa filters, torch kernels), so the first live frame is not slower."""
        row = CausalMusicFeatures(self.sample_rate, self.beat_phase).push(
            np.zeros(self.sample_rate // 10, np.float32)
        )[:1]
        music = torch.from_numpy(row).to(self.prev)
        self.model.step(self.prev, music, self.model.init_state(1), self.backbone_step)

    def push(self, samples: np.ndarray, arrival: float | None = None, last: bool = False) -> int:
        """Feed audio delivered at wall time ``arrival`` (default now); returns the poses emitted."""
        arrival = time.perf_counter() if arrival is None else arrival
        frames = self.features.push(samples, last=last)
        for row in frames:
            music = torch.from_numpy(row).to(self.prev)[None]
            self.prev, self.state = self.model.step(self.prev, music, self.state, self.backbone_step)
            self.latency_ms.append((time.perf_counter() - arrival) * 1e3)
            self.poses.append(self.prev[0].clone())
            self.music.append(row)
        return len(frames)

    @property
    def num_frames(self) -> int:
        return len(self.poses)

    def tokens(self) -> torch.Tensor:
        """The dance so far, (T, 24, 12)."""
        return torch.stack(self.poses) if self.poses else torch.zeros(0, 24, POSE_CHANNELS)

    def music_features(self) -> torch.Tensor:
        """The features danced to, (T, 34) (36 with the beat phase)."""
        return torch.from_numpy(np.stack(self.music)) if self.music else torch.zeros(0, self.features.width)
