"""Music as it arrives: chunks of mono float32 samples from a file or standard input.

* a path: any format the one audio reader opens
  (:func:`~skeleton_mamba.tasks.motion.music.audio_io.open_audio`: wav, flac, ogg, mp3), checked and read
  block by block;
* ``-`` : a WAV stream on standard input (PCM 8/16/24/32-bit or float, 1 to 8 channels, any rate in the
  reader's bounds), read as it comes (the RIFF header is parsed sequentially, so a pipe works);
* ``-`` with ``raw_rate``: headerless signed 16-bit little-endian mono PCM at ``raw_rate`` Hz.

Channels are averaged to mono. With ``realtime`` the chunks are released at the pace of the music (chunk
k when its last sample would have been played), as from a live source; otherwise as fast as they are read.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skeleton_mamba.tasks.motion.music.audio_io import (
    MAX_DURATION_S,
    AudioFileError,
    AudioReader,
    check_format,
    open_audio,
    open_wav_stream,
)

__all__ = ["AudioChunk", "AudioSource"]


@dataclass
class AudioChunk:
    """``samples`` (n,) float32 mono and the wall time (``time.perf_counter``) it was delivered."""

    samples: np.ndarray
    arrival: float


class AudioSource:
    """Iterate over :class:`AudioChunk` of about ``chunk_s`` seconds from ``source``.

    Args:
        source: a file path or ``-`` (standard input).
        chunk_s: chunk length in seconds.
        realtime: pace the chunks at the music's rate.
        raw_rate: with ``-``, read headerless 16-bit mono PCM at this rate instead of a WAV stream.

    Raises:
        FileNotFoundError: no such file.
        AudioFileError: a refused header (rate, channels, duration, encoding) or not a WAV stream.
    """

    def __init__(
        self, source: str, chunk_s: float = 0.02, realtime: bool = False, raw_rate: int | None = None
    ):
        if not chunk_s > 0:
            raise ValueError(f"chunk length must be positive, got {chunk_s} s")
        self.source = source
        self.realtime = realtime
        self.raw_rate = raw_rate
        self._reader: AudioReader | None = None
        if source == "-":
            self._stdin = sys.stdin.buffer
            if raw_rate is not None:
                check_format("standard input (--raw-rate)", raw_rate, 1)
                self.sample_rate, self.channels = int(raw_rate), 1
            else:
                try:
                    self._reader = open_wav_stream(self._stdin)
                except AudioFileError as err:
                    raise AudioFileError(f"{err}; for raw PCM pass --raw-rate") from err
        else:
            if not Path(source).is_file():
                raise FileNotFoundError(f"{source}: music file not found")
            self._reader = open_audio(source)
        if self._reader is not None:
            self.sample_rate, self.channels = self._reader.info.sample_rate, self._reader.info.channels
        self.chunk = max(1, int(round(chunk_s * self.sample_rate)))

    def _raw_blocks(self) -> Iterator[np.ndarray]:
        """Headerless s16le mono, at most :data:`MAX_DURATION_S` (an odd trailing byte is dropped)."""
        left = int(MAX_DURATION_S * self.sample_rate)
        while left > 0 and (data := self._stdin.read(2 * min(self.chunk, left))):
            x = np.frombuffer(data[: len(data) // 2 * 2], dtype="<i2").astype(np.float32) / 32768.0
            left -= len(x)
            yield x[:, None]

    def __iter__(self) -> Iterator[AudioChunk]:
        start = time.perf_counter()
        received = 0
        blocks = self._raw_blocks() if self._reader is None else self._reader.blocks(block_frames=self.chunk)
        try:
            for block in blocks:
                samples = block.mean(axis=1) if block.shape[1] > 1 else block[:, 0]
                received += len(samples)
                if self.realtime:
                    delay = start + received / self.sample_rate - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
                yield AudioChunk(samples, time.perf_counter())
        finally:
            if self._reader is not None:
                self._reader.close()
