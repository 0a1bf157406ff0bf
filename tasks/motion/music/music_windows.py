"""The 35-d music feature of a long track, analysed window by window: memory independent of its length.

A whole-track analysis holds the decoded audio, its resampled copy and librosa's spectrograms of the whole
track at once (gigabytes for an hour). Here the file is decoded once, in blocks; every :data:`WINDOW_S`
seconds of audio are resampled and analysed with :data:`CONTEXT_S` seconds of the neighbouring audio on each
side (:func:`~.features.frame_features`: onset envelope, MFCC, CENS chroma) and only the window's own frames
are kept; the onset peaks, the tempo prior and the beats are then found on the whole track's onset envelope
(:func:`~.features.features_from_frames`, a few floats per frame), as for a short track; the tempo prior
reads the time-averaged tempogram, summed window by window (:func:`mean_tempogram`), not the whole
``(win, T)`` tempogram librosa would hold.

The context covers the spectral frames, the constant-Q filters and the CENS smoothing, so the frames equal
the whole-track analysis except where librosa's decibel floor (80 dB below the loudest frame it sees) falls
differently: a window sees its own loudest frame, not the track's
    (``tests/motion/music/test_music_windows.py``
measures the difference on a real recording).
"""

from __future__ import annotations

import itertools
import os

import numpy as np

from skeleton_mamba.tasks.motion.music.audio_io import open_audio
from skeleton_mamba.tasks.motion.music.features import HOP_LENGTH, frame_features
from skeleton_mamba.tasks.motion.music.jit_lock import librosa_calls

__all__ = ["CONTEXT_S", "LONG_TRACK_S", "WINDOW_S", "mean_tempogram", "windowed_frame_features"]

WINDOW_S = 60  # seconds of audio analysed at a time (whole seconds: windows start on frame boundaries)
CONTEXT_S = 10  # seconds of neighbouring audio each side of a window
LONG_TRACK_S = 180.0  # tracks (or parts) longer than this are analysed in windows


def windowed_frame_features(
    path: str | os.PathLike,
    fps: int,
    duration_s: float | None = None,
    window_s: int = WINDOW_S,
    context_s: int = CONTEXT_S,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-frame parts of ``path``'s feature at ``fps`` (onset envelope ``(T,)``, MFCC ``(T, 20)``,
    chroma ``(T, 12)``; of the first ``duration_s`` seconds when given), analysed in windows (module
    docstring).

    Raises:
        FileNotFoundError, AudioFileError: as :func:`~.audio_io.open_audio` and its blocks.
        ValueError: no samples, or windows that are not whole seconds.
    """
    if int(window_s) != window_s or int(context_s) != context_s or window_s < 1 or context_s < 0:
        raise ValueError(f"window_s and context_s must be whole seconds, got {window_s} and {context_s}")
    sr = int(fps) * HOP_LENGTH
    parts: list[tuple[np.ndarray, ...]] = []
    with open_audio(path) as reader:
        rate = reader.info.sample_rate
        limit = None if duration_s is None else int(round(duration_s * rate))
        blocks = (block.mean(axis=1, dtype=np.float32) for block in reader.blocks(0, limit))
        buffer, start, ended = np.zeros(0, np.float32), 0, False  # mono samples from sample `start` on
        for k in itertools.count():
            need = ((k + 1) * window_s + context_s) * rate  # the window and the context after it
            pieces, have = [buffer], start + len(buffer)
            while not ended and have < need:
                block = next(blocks, None)
                ended = block is None
                if block is not None:
                    pieces.append(block)
                    have += len(block)
            buffer = np.concatenate(pieces)
            if have <= k * window_s * rate:  # the previous window ended the track
                break
            first_s = max(0, k * window_s - context_s)
            segment = buffer[first_s * rate - start : need - start]
            with librosa_calls() as librosa:
                y = segment if rate == sr else librosa.resample(segment, orig_sr=rate, target_sr=sr)
            frames = frame_features(y, sr)
            last = ended and have < need  # the track ends inside this window or its context: keep all
            keep = slice(
                (k * window_s - first_s) * fps, None if last else (k * window_s - first_s + window_s) * fps
            )
            parts.append(tuple(part[keep] for part in frames))
            if last:
                break
            drop = ((k + 1) * window_s - context_s) * rate - start  # samples no later window reads
            if drop > 0:
                buffer, start = buffer[drop:], start + drop
    if not parts or not len(parts[0][0]):
        raise ValueError(f"{path}: the audio holds no samples")
    envelope, mfcc, chroma = (np.concatenate([part[i] for part in parts]) for i in range(3))
    return envelope, mfcc, chroma


def mean_tempogram(envelope: np.ndarray, fps: int, chunk: int = 4096, ac_size_s: float = 8.0) -> np.ndarray:
    """librosa's tempogram of ``envelope`` (centred, 8 s autocorrelation windows, as
    ``librosa.feature.tempo`` computes it) averaged over time, ``(win, 1)``: summed ``chunk`` columns at a
    time, so memory does not grow with the envelope's length."""
    sr = int(fps) * HOP_LENGTH
    envelope = np.asarray(envelope, dtype=np.float64)
    n = len(envelope)
    with librosa_calls() as librosa:
        win = int(librosa.time_to_frames(ac_size_s, sr=sr, hop_length=HOP_LENGTH).item())
        padded = np.pad(envelope, win // 2, mode="linear_ramp", end_values=[0, 0])  # librosa's centring
        total = np.zeros(win)
        for a in range(0, n, chunk):
            b = min(n, a + chunk)  # columns a..b-1 read padded[t : t + win]
            part = librosa.feature.tempogram(
                onset_envelope=padded[a : b + win - 1],
                sr=sr,
                hop_length=HOP_LENGTH,
                win_length=win,
                center=False,
            )
            total += part.sum(axis=-1)
    return (total / max(n, 1))[:, None]
