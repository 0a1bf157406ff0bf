"""Causal music features for live music-to-dance: frame t uses audio up to the end of frame t only.

The offline 35-d FACT / EDGE feature (``tasks.motion.music.features``) looks ahead: centred STFT frames,
``chroma_cens`` smoothing, and beat tracking over the whole track. Here every frame is computed from
one window that *ends* at the frame's last sample, and nothing else:

* audio: mono, resampled to ``SR = 30 * 512 = 15360`` Hz so one hop of ``HOP = 512`` samples is one
  pose frame at 30 fps (the rate of the offline feature at 30 fps);
* frame t covers the new samples ``[t * HOP, (t + 1) * HOP)``; its STFT window is the ``N_FFT = 2048``
  samples ending at ``(t + 1) * HOP`` (Hann, zeros before the start of the music), i.e. librosa's
  ``stft(center=False)`` of the signal left-padded with ``N_FFT - HOP`` zeros;
* per frame (34 columns): ``0`` onset strength, the mean over mel bands of
  ``max(0, logmel_t - logmel_{t-1})`` (``librosa.onset.onset_strength(lag=1, max_size=1,
  center=False, aggregate=mean)``; 0 for the first frame); ``1-20`` 20 MFCCs of ``logmel_t``
  (``librosa.feature.mfcc``); ``21-32`` 12-bin chroma (``librosa.feature.chroma_stft``, tuning fixed
  at 0, per-frame max normalisation); ``33`` log RMS energy;
  ``logmel = power_to_db(128-band mel power, ref 1, no top_db clipping)`` (clipping against the
  track's maximum would look ahead).

With ``beat_phase=True`` two more columns follow (36 in all): the phase of the beat as a causal tracker
estimates it from the onset strengths so far (:mod:`.beat_phase`), so a dancer can stop on the next beat
rather than after it.

Latency: pose frame t needs the audio up to ``(t + 1) * HOP``, so the algorithmic latency is one hop
(33.3 ms) after the frame's start (0 ms after its last sample), plus the resampler's delay when the
input is not at ``SR`` (a low-quality ``soxr`` stream: 17 to 22 ms from 22.05 or 44.1 kHz,
reported by :class:`CausalMusicFeatures`), plus the size of the chunks in which the audio arrives.
:func:`music_features` computes the same features offline (training data) by pushing the whole
track through the same streaming extractor.
"""

from __future__ import annotations

import numpy as np
import soxr

from skeleton_mamba.tasks.motion.music.jit_lock import librosa_calls
from skeleton_mamba.tasks.stream.beat_phase import NUM_BEAT_FEATURES, CausalBeatPhase

__all__ = [
    "FPS",
    "HOP",
    "N_FFT",
    "NUM_FEATURES",
    "SR",
    "CausalMusicFeatures",
    "beat_phase_for",
    "feature_width",
    "music_features",
]

FPS = 30
HOP = 512
SR = FPS * HOP
N_FFT = 2048
N_MELS = 128
NUM_FEATURES = 34


def feature_width(beat_phase: bool) -> int:
    """Columns per frame: 34, or 36 with the beat phase."""
    return NUM_FEATURES + (NUM_BEAT_FEATURES if beat_phase else 0)


def beat_phase_for(music_dim: int) -> bool:
    """Whether a dancer with ``music_dim`` inputs per frame reads the beat phase (36) or not (34).

    Raises:
        ValueError: any other width.
    """
    if music_dim not in (feature_width(False), feature_width(True)):
        raise ValueError(
            f"the live dancer's music features are {feature_width(False)} or {feature_width(True)} (with the "
            f"beat phase) per frame, got {music_dim}"
        )
    return music_dim == feature_width(True)


class CausalMusicFeatures:
    """Push audio chunks in, get the features of every completed frame out.

    Args:
        sample_rate: rate of the pushed audio (resampled to :data:`SR` with a streaming ``soxr``
            resampler when different).
        beat_phase: append the causal beat phase (2 columns, :mod:`.beat_phase`).

    Example::

        extractor = CausalMusicFeatures(44100)
        for chunk in chunks:                    # float32 mono, any sizes
            frames = extractor.push(chunk)      # (n, 34), n >= 0 completed frames
    """

    def __init__(self, sample_rate: int = SR, beat_phase: bool = False):
        if sample_rate <= 0:
            raise ValueError(f"sample rate must be positive, got {sample_rate}")
        self.sample_rate = int(sample_rate)
        self.width = feature_width(beat_phase)
        self.beat = CausalBeatPhase() if beat_phase else None
        with librosa_calls() as librosa:
            self.window = librosa.filters.get_window("hann", N_FFT, fftbins=True).astype(np.float64)
            self.mel = librosa.filters.mel(sr=SR, n_fft=N_FFT, n_mels=N_MELS)
            self.chroma = librosa.filters.chroma(sr=SR, n_fft=N_FFT, tuning=0.0)
        self.resampler = None
        if self.sample_rate != SR:
            self.resampler = soxr.ResampleStream(self.sample_rate, SR, 1, dtype="float32", quality="LQ")
        self.buffer = np.zeros(N_FFT - HOP, dtype=np.float32)  # the window's samples before this frame
        self.previous_logmel: np.ndarray | None = None
        self.frames = 0
        self.resampler_delay_s = 0.0  # the largest delay of the streaming resampler so far

    def push(self, chunk: np.ndarray, last: bool = False) -> np.ndarray:
        """Append mono samples; return the (n, 34 or 36) float32 features of the frames they complete.

        ``last=True`` flushes the resampler (the end of the music); a trailing partial hop is dropped.
        """
        chunk = np.asarray(chunk, dtype=np.float32).reshape(-1)
        if not np.isfinite(chunk).all():
            raise ValueError("audio chunk holds NaN or Inf samples")
        if self.resampler is not None:
            chunk = self.resampler.resample_chunk(chunk, last=last)
            self.resampler_delay_s = max(self.resampler_delay_s, float(self.resampler.delay()) / SR)
        self.buffer = np.concatenate([self.buffer, chunk])
        count = (len(self.buffer) - (N_FFT - HOP)) // HOP
        if count <= 0:
            return np.zeros((0, self.width), dtype=np.float32)
        frames = np.lib.stride_tricks.sliding_window_view(self.buffer, N_FFT)[: count * HOP : HOP]
        out = self._features(frames)
        if self.beat is not None:
            out = np.concatenate([out, self.beat.push(out[:, 0])], axis=1)
        self.buffer = self.buffer[count * HOP :]
        self.frames += count
        return out

    def _features(self, frames: np.ndarray) -> np.ndarray:
        """(n, N_FFT) windows -> (n, 34) features; keeps the last log-mel frame for the onset flux."""
        power = np.abs(np.fft.rfft(frames.astype(np.float64) * self.window, axis=1)) ** 2  # (n, 1025)
        with librosa_calls(warm_path="stream features") as librosa:  # locked on the first frame only
            logmel = librosa.power_to_db(power @ self.mel.T, ref=1.0, top_db=None)  # (n, 128)
            mfcc = librosa.feature.mfcc(S=logmel.T, n_mfcc=20).T  # (n, 20)
            chroma = librosa.util.normalize(power @ self.chroma.T, norm=np.inf, axis=1)  # (n, 12)
        previous = logmel[:1] if self.previous_logmel is None else self.previous_logmel[None]
        flux = np.maximum(0.0, np.diff(np.concatenate([previous, logmel]), axis=0)).mean(axis=1)
        self.previous_logmel = logmel[-1]
        rms = np.log(np.sqrt(np.mean(frames.astype(np.float64) ** 2, axis=1)) + 1e-5)
        return np.concatenate([flux[:, None], mfcc, chroma, rms[:, None]], axis=1).astype(np.float32)


def music_features(
    audio: np.ndarray, sample_rate: int, chunk: int = 4096, beat_phase: bool = False
) -> np.ndarray:
    """The causal features of a whole track, (T, 34) float32 at 30 fps (T = complete hops at SR; (T, 36)
    with ``beat_phase``).

    Pushes ``audio`` through :class:`CausalMusicFeatures` in chunks of ``chunk`` samples, so the
    result is what a live stream of the same audio yields.
    """
    extractor = CausalMusicFeatures(sample_rate, beat_phase)
    audio = np.asarray(audio, dtype=np.float32).reshape(-1)
    parts = [extractor.push(audio[s : s + chunk]) for s in range(0, len(audio), chunk)]
    parts.append(extractor.push(np.zeros(0, dtype=np.float32), last=True))
    return np.concatenate(parts)
