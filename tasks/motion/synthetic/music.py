"""Synthetic dance music at a given tempo: drums and bass, written as wav (soundfile). SYNTHETIC data.

Beat ``k`` lies at ``t_k = k * 60 / bpm`` seconds (the first beat at 0). In every 4/4 bar:

* kick: on every beat, a sine sweeping from 150 Hz down to 50 Hz with a 0.12 s exponential decay;
* snare: on beats 2 and 4 of the bar, white noise with a 0.08 s decay plus a 180 Hz tone;
* hi-hat: on every eighth note (the beats and half-way between them), quiet first-differenced noise
  (a crude high-pass) with a 0.03 s decay;
* bass: one sawtooth-ish note per beat (first three harmonics), held for 80 % of the beat, following a
  four-bar root progression (A1, F1, C2, G1) chosen per seed.

The mix is normalised to a peak of 0.9. Everything is deterministic given the seed.

:func:`write_tone` writes a plain sine tone (16-bit PCM mono wav), the audio of the readers' examples.
"""

from __future__ import annotations

import wave
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
import soundfile as sf

from skeleton_mamba.io.atomic import atomic_path

__all__ = ["SyntheticTrack", "synthesize_music", "write_music", "write_tone", "beat_times"]

_PROGRESSIONS = ((55.0, 43.65, 65.41, 49.0), (43.65, 49.0, 55.0, 65.41), (65.41, 55.0, 43.65, 49.0))


@dataclass
class SyntheticTrack:
    """A synthesised track and its schedule (seconds).

    Attributes:
        audio: (N,) float32 mono samples in [-1, 1].
        sr: sample rate (Hz).
        bpm: tempo.
        beats: beat times; kicks are on every beat.
        snares: snare times (beats 2 and 4 of each bar).
        hats: hi-hat times (every eighth note).
    """

    audio: np.ndarray
    sr: int
    bpm: float
    beats: np.ndarray
    snares: np.ndarray
    hats: np.ndarray

    @property
    def duration(self) -> float:
        return len(self.audio) / self.sr


def beat_times(bpm: float, duration_s: float) -> np.ndarray:
    """Times ``k * 60 / bpm`` of all beats in ``[0, duration_s)``."""
    if bpm <= 0 or duration_s <= 0:
        raise ValueError(f"bpm and duration must be positive, got bpm={bpm}, duration={duration_s}")
    period = 60.0 / bpm
    return np.arange(0.0, duration_s - 1e-9, period)


def _add(out: np.ndarray, start: int, sound: np.ndarray) -> None:
    end = min(len(out), start + len(sound))
    if end > start:
        out[start:end] += sound[: end - start]


def synthesize_music(bpm: float, duration_s: float, sr: int = 22050, seed: int = 0) -> SyntheticTrack:
    """Drums and bass at ``bpm`` (see the module docstring)."""
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * sr))
    out = np.zeros(n)
    period = 60.0 / bpm
    beats = beat_times(bpm, duration_s)

    t = np.arange(int(0.25 * sr)) / sr
    freq = 50.0 + 100.0 * np.exp(-t / 0.03)  # 150 Hz -> 50 Hz sweep
    kick = np.sin(2 * np.pi * np.cumsum(freq) / sr) * np.exp(-t / 0.12)
    ts = np.arange(int(0.2 * sr)) / sr
    snare = (0.6 * rng.standard_normal(len(ts)) + 0.4 * np.sin(2 * np.pi * 180 * ts)) * np.exp(-ts / 0.08)
    th = np.arange(int(0.06 * sr)) / sr
    hat = np.diff(rng.standard_normal(len(th) + 1)) * np.exp(-th / 0.03)

    progression = _PROGRESSIONS[seed % len(_PROGRESSIONS)]
    note_len = int(0.8 * period * sr)
    tb = np.arange(note_len) / sr
    envelope = np.minimum(1.0, tb / 0.01) * np.exp(-tb / (0.5 * period))
    snares, hats = [], []
    for k, beat in enumerate(beats):
        start = int(round(beat * sr))
        _add(out, start, 1.0 * kick)
        if k % 4 in (1, 3):
            _add(out, start, 0.5 * snare)
            snares.append(beat)
        for half in (0.0, 0.5):
            when = beat + half * period
            if when < duration_s:
                _add(out, int(round(when * sr)), 0.15 * hat)
                hats.append(when)
        f0 = progression[(k // 4) % len(progression)]
        bass = sum(np.sin(2 * np.pi * h * f0 * tb) / h for h in (1, 2, 3))
        _add(out, start, 0.35 * bass * envelope)
    out *= 0.9 / max(np.abs(out).max(), 1e-9)
    return SyntheticTrack(out.astype(np.float32), sr, float(bpm), beats, np.array(snares), np.array(hats))


def write_music(path: str | PathLike[str], track: SyntheticTrack) -> Path:
    """Write a track as 16-bit PCM wav (atomically)."""

    path = Path(path)
    with atomic_path(path) as tmp:
        sf.write(tmp, track.audio, track.sr, subtype="PCM_16")
    return path


def write_tone(
    path: str | PathLike[str], seconds: float = 0.5, sr: int = 16000, hz: float = 440.0, peak: float = 0.5
) -> Path:
    """Write ``seconds`` of a ``hz`` sine of amplitude ``peak`` as 16-bit PCM mono wav at ``sr`` Hz
    (atomically).

    Examples:
        >>> import tempfile
        >>> path = write_tone(Path(tempfile.mkdtemp()) / "tone.wav")  # 0.5 s of 440 Hz, 16 kHz
        >>> path.name, path.stat().st_size  # a 44-byte header and 8000 two-byte samples
        ('tone.wav', 16044)
    """
    path = Path(path)
    t = np.arange(int(round(seconds * sr))) / sr
    samples = (peak * np.sin(2 * np.pi * hz * t) * 32767).astype("<i2")
    with atomic_path(path) as tmp, wave.open(str(tmp), "wb") as f:
        f.setnchannels(1)
        f.setsampwidth(2)
        f.setframerate(sr)
        f.writeframes(samples.tobytes())
    return path
