"""Music as it arrives: chunks of mono float32 samples from a file or standard input.

* a path: any format ``soundfile`` reads (wav, flac, ogg), read block by block;
* ``-`` : a WAV stream on standard input (16-bit PCM, any rate and channel count), read as it
  comes (``wave`` reads the header sequentially, so a pipe works);
* ``-`` with ``raw_rate``: headerless signed 16-bit little-endian mono PCM at ``raw_rate`` Hz.

With ``realtime`` the chunks are released at the pace of the music (chunk k when its last sample
would have been played), as from a live source; otherwise as fast as they are read.
"""

from __future__ import annotations

import sys
import time
import wave
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import soundfile as sf

__all__ = ["AudioChunk", "AudioSource"]


@dataclass
class AudioChunk:
    """``samples`` (n,) float32 mono and the wall time (``time.perf_counter``) it was delivered."""

    samples: np.ndarray
    arrival: float


def _pcm16(data: bytes, channels: int) -> np.ndarray:
    """Interleaved 16-bit PCM bytes -> mono float32 in [-1, 1)."""
    x = np.frombuffer(data[: len(data) // (2 * channels) * 2 * channels], dtype="<i2").astype(np.float32)
    return x.reshape(-1, channels).mean(axis=1) / 32768.0


class AudioSource:
    """Iterate over :class:`AudioChunk` of about ``chunk_s`` seconds from ``source``.

    Args:
        source: a file path or ``-`` (standard input).
        chunk_s: chunk length in seconds.
        realtime: pace the chunks at the music's rate.
        raw_rate: with ``-``, read headerless 16-bit mono PCM at this rate instead of a WAV stream.
    """

    def __init__(
        self, source: str, chunk_s: float = 0.02, realtime: bool = False, raw_rate: int | None = None
    ):
        if chunk_s <= 0:
            raise ValueError(f"chunk length must be positive, got {chunk_s} s")
        self.source = source
        self.realtime = realtime
        self.raw_rate = raw_rate
        self._wave = None
        self._file = None
        if source == "-":
            stdin = sys.stdin.buffer
            if raw_rate is not None:
                self.sample_rate, self.channels = int(raw_rate), 1
            else:
                try:
                    self._wave = wave.open(stdin, "rb")
                except (wave.Error, EOFError) as err:
                    raise ValueError(
                        f"standard input is not a WAV stream ({err}); for raw PCM pass --raw-rate"
                    ) from err
                bits = 8 * self._wave.getsampwidth()
                if bits != 16:
                    raise ValueError(f"standard input: only 16-bit PCM WAV is read, got {bits} bits")
                self.sample_rate, self.channels = self._wave.getframerate(), self._wave.getnchannels()
            self._stdin = stdin
        else:
            path = Path(source)
            if not path.is_file():
                raise FileNotFoundError(f"{path}: music file not found")
            try:
                self._file = sf.SoundFile(path)
            except Exception as err:  # soundfile raises its own LibsndfileError / RuntimeError
                raise ValueError(f"{path}: cannot decode audio ({err})") from err
            self.sample_rate, self.channels = self._file.samplerate, self._file.channels
        self.chunk = max(1, int(round(chunk_s * self.sample_rate)))

    def _read(self) -> np.ndarray | None:
        if self._file is not None:
            block = self._file.read(self.chunk, dtype="float32", always_2d=True)
            return block.mean(axis=1) if len(block) else None
        if self._wave is not None:
            data = self._wave.readframes(self.chunk)
        else:
            data = self._stdin.read(2 * self.chunk)
        return _pcm16(data, self.channels) if data else None

    def __iter__(self) -> Iterator[AudioChunk]:
        start = time.perf_counter()
        received = 0
        try:
            while (samples := self._read()) is not None:
                received += len(samples)
                if self.realtime:
                    delay = start + received / self.sample_rate - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
                yield AudioChunk(samples, time.perf_counter())
        finally:
            if self._file is not None:
                self._file.close()
