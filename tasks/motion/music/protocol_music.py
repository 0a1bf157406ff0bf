"""Music beats and features as the dance-evaluation protocols compute them (see
:mod:`skeleton_mamba.tasks.motion.metrics.protocols`).

- :func:`fact_beats`: column 34 of the 60 fps 35-d feature (:func:`.features.extract_music_features`: AIST
  ``start_bpm``, tightness 100), FACT's ``audio_feature[:, -1]`` (mint tools/calculate_beat_scores.py).
- :func:`bailando_beats`: [Bailando]'s own recipe (Bailando _prepro_aistpp.py ``extract_acoustic_feature``,
  extractor.py): audio at 30,720 Hz (60 fps x hop 512), ``librosa.effects.hpss``, onset strength of the
  **percussive** part aggregated with ``np.median``, ``librosa.beat.beat_track`` with its defaults
  (``start_bpm`` 120, tightness 100); column 53 of its 438-d feature. Bailando decodes with essentia's
  ``MonoLoader``; here librosa decodes and resamples, so a beat can move by a frame where they differ.
- :func:`edge_slice_features`: [EDGE]'s per-slice 35-d features (EDGE data/slice.py ``slice_audio``, test.py,
  data/audio_extraction/baseline_features.py ``extract``): the track at its own sample rate is cut into 5 s
  slices every 2.5 s (:func:`edge_slice_starts`: ``while start <= len - window``), each slice written as a
  16-bit wav and read back at 15,360 Hz, its features computed **on the slice alone** (so the beat tracker
  restarts in every slice) and cut to 150 rows. ``start_bpm``: EDGE's ``_get_tempo`` reads the 5th ``_``
  field of the slice name (``<stem>_slice<i>``), so an AIST++ sequence name gives its music id's tempo, and
  anything else (e.g. ``mBR0.wav``) falls back to ``librosa`` tempo of the slice loaded at 22,050 Hz,
  unfolded.

Results are cached like the 35-d features (:mod:`skeleton_mamba.tasks.motion.io.cache`), keyed by file content
and settings.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
import soundfile as sf

from skeleton_mamba.tasks.motion.io.cache import FeatureCache
from skeleton_mamba.tasks.motion.music.features import (
    HOP_LENGTH,
    NUM_MUSIC_FEATURES,
    aist_start_bpm,
    beat_frames,
    compute_music_features,
    extract_music_features,
    load_audio,
)
from skeleton_mamba.tasks.motion.music.jit_lock import librosa_calls, librosa_version

__all__ = [
    "EDGE_SLICE_FRAMES",
    "bailando_beats",
    "edge_slice_beats",
    "edge_slice_features",
    "edge_slice_starts",
    "edge_start_bpm",
    "fact_beats",
]

BAILANDO_FPS = 60
EDGE_FPS = 30
EDGE_SLICE_SECONDS = 5.0
EDGE_STRIDE_SECONDS = 2.5
EDGE_SLICE_FRAMES = 150  # EDGE chops each slice's features to 5 s x 30 fps
_EDGE_FALLBACK_SR = 22050  # librosa.load's default rate, used by EDGE's tempo fallback
_AIST_GENRES = ("mBR", "mPO", "mLO", "mMH", "mLH", "mWA", "mKR", "mJS", "mJB", "mHO")
_VERSION = 1


def fact_beats(path: str | os.PathLike, cache_dir: str | os.PathLike | None = None) -> np.ndarray:
    """Beat frames (60 fps) of the whole track, FACT's recipe (column 34 of the 35-d feature)."""
    return extract_music_features(path, fps=60, cache_dir=cache_dir).beat_frames


def bailando_beats(
    path: str | os.PathLike, cache_dir: str | os.PathLike | None = None, use_cache: bool = True
) -> np.ndarray:
    """Beat frames (60 fps) of the whole track from the HPSS-percussive onset envelope (Bailando's recipe)."""
    cache = FeatureCache("music", cache_dir, enabled=use_cache)
    key = cache.key(path, {"kind": "bailando_beats", "version": _VERSION, "librosa": librosa_version()})
    onehot = cache.load(key)
    if onehot is None or onehot.ndim != 1:
        sr = BAILANDO_FPS * HOP_LENGTH
        y = load_audio(path, sr)
        with librosa_calls() as librosa:
            _, percussive = librosa.effects.hpss(y)
            envelope = librosa.onset.onset_strength(y=percussive, aggregate=np.median, sr=sr)
            _, beats = librosa.beat.beat_track(onset_envelope=envelope, sr=sr)
        onehot = np.zeros(len(envelope), dtype=np.float32)
        onehot[beats] = 1.0
        cache.store(key, onehot)
    return np.flatnonzero(onehot)


def edge_slice_starts(length: int, rate: float) -> range:
    """[EDGE]'s slice starts (EDGE data/slice.py ``slice_audio`` / ``slice_motion``) in a ``length``-long
    signal at ``rate`` samples (or frames) per second: window ``int(5 * rate)``, stride ``int(2.5 * rate)``,
    starts ``0, stride, ...`` kept while ``start <= length - window``.

    ``slice_audio`` applies it at the file's sample rate, ``slice_motion`` at 60 fps (and stops at the audio
    slice count), so motion and music of the same duration give the same count, and slice ``i`` of both
    starts ``2.5 i`` seconds in (exactly, where ``2.5 * rate`` is an integer).
    """
    window, stride = int(EDGE_SLICE_SECONDS * rate), int(EDGE_STRIDE_SECONDS * rate)
    if window < 1 or stride < 1:
        raise ValueError(f"EDGE slicing needs a rate of at least 0.4 per second, got {rate}")
    return range(0, int(length) - window + 1, stride)


def edge_start_bpm(slice_name: str) -> float | None:
    """EDGE's ``_get_tempo``: the AIST tempo of the 5th ``_`` field of a slice name, else ``None``."""
    fields = slice_name.split("_")
    if len(fields) < 5 or len(fields[4]) != 4 or fields[4][:3] not in _AIST_GENRES:
        return None
    return aist_start_bpm(fields[4])


def _wav16_roundtrip(audio: np.ndarray, sr: int, target_sr: int) -> np.ndarray:
    """``sf.write`` of a slice as a (16-bit PCM) wav, then ``librosa.load(..., sr=target_sr)``, in memory."""
    buffer = io.BytesIO()
    sf.write(buffer, audio, sr, format="WAV")  # soundfile's default wav subtype is PCM_16, as in EDGE
    buffer.seek(0)
    with librosa_calls() as librosa:
        y, _ = librosa.load(buffer, sr=target_sr)
    return y


def edge_slice_features(
    path: str | os.PathLike,
    start_s: float = 0.0,
    duration_s: float | None = None,
    cache_dir: str | os.PathLike | None = None,
    use_cache: bool = True,
) -> np.ndarray:
    """EDGE's per-slice 35-d features of ``path`` (from ``start_s``, for ``duration_s``): ``(S, 150, 35)``.

    Slice ``i`` covers ``[start_s + 2.5 i, start_s + 2.5 i + 5)`` seconds; ``S = 0`` when less than 5 s of
    audio remains.
    """
    path = Path(path)
    settings = {"kind": "edge_slices", "version": _VERSION, "start_s": float(start_s),
                "duration_s": None if duration_s is None else float(duration_s),
                "librosa": librosa_version()}  # fmt: skip
    cache = FeatureCache("music", cache_dir, enabled=use_cache)
    key = cache.key(path, settings)
    cached = cache.load(key)
    slice_shape = (EDGE_SLICE_FRAMES, NUM_MUSIC_FEATURES)
    if cached is not None and cached.ndim == 3 and cached.shape[1:] == slice_shape:
        return cached
    with librosa_calls() as librosa:
        native_sr = int(librosa.get_samplerate(path))
    audio = load_audio(path, native_sr)
    audio = audio[int(start_s * native_sr) :]
    if duration_s is not None:
        audio = audio[: int(duration_s * native_sr)]
    window = int(EDGE_SLICE_SECONDS * native_sr)
    slices = []
    for i, start in enumerate(edge_slice_starts(len(audio), native_sr)):
        piece = audio[start : start + window]
        y = _wav16_roundtrip(piece, native_sr, EDGE_FPS * HOP_LENGTH)
        bpm = edge_start_bpm(f"{path.stem}_slice{i}")
        if bpm is None:
            with librosa_calls() as librosa:
                fallback = _wav16_roundtrip(piece, native_sr, _EDGE_FALLBACK_SR)
                bpm = float(librosa.feature.tempo(y=fallback, sr=_EDGE_FALLBACK_SR)[0])
        features = compute_music_features(y, EDGE_FPS, start_bpm=bpm, bpm_range=None).features
        if len(features) < EDGE_SLICE_FRAMES:
            raise ValueError(f"{path}: slice {i} gives {len(features)} feature rows, EDGE expects 150")
        slices.append(features[:EDGE_SLICE_FRAMES])
    out = np.stack(slices) if slices else np.zeros((0, *slice_shape), np.float32)
    cache.store(key, out)
    return out


def edge_slice_beats(features: np.ndarray) -> list[np.ndarray]:
    """Beat frames (30 fps, relative to each slice) from :func:`edge_slice_features` output."""
    return [beat_frames(f) for f in features]
