"""The 35-d librosa music feature of FACT (60 fps) and EDGE (30 fps), with tempo and beats.

Recipe (google-research/mint tools/preprocessing.py; Stanford-TML/EDGE data/audio_extraction/
baseline_features.py): the audio is loaded at ``SR = fps * 512`` Hz so one STFT hop of
512 samples is one motion frame, then per frame

========  =======================================================================
columns   content
========  =======================================================================
0         onset-strength envelope (``librosa.onset.onset_strength``)
1-20      20 MFCCs (``librosa.feature.mfcc``)
21-32     12-bin ``chroma_cens`` (hop 512)
33        one-hot onset peaks (``librosa.onset.onset_detect`` on the envelope)
34        one-hot beats (``librosa.beat.beat_track`` on the envelope, ``start_bpm``, tightness 100)
========  =======================================================================

``start_bpm`` comes from the AIST music id when the file name carries one (:func:`aist_start_bpm`);
otherwise it is librosa's tempo estimate as detected, as EDGE's fallback does (``bpm_range`` optionally
folds that prior into a tempo octave first). The reported tempo (:attr:`MusicAnalysis.tempo_bpm`) is the
tempo detected in the beats: the slope of a least-squares line through the beat times, which is not
quantised to whole frames like librosa's estimate (at 30 fps a 132 BPM track reads 128.6 BPM there,
133.2 BPM here). Folding it into the dance range 80-170 BPM (AIST++'s range; beat trackers often lock
onto half or double the tempo) is a separate, labelled value, :attr:`MusicAnalysis.dance_tempo_bpm`: a
68 BPM track has tempo 68 and dance-range tempo 136. Audio with fewer than two beats has no tempo, and
:attr:`MusicAnalysis.tempo_note` says why (silent, too short, no steady beat).

pyproject.toml requires ``librosa>=0.10.2``, the first version whose features and beats match the later ones;
the cache key holds the version.

Beat frames move with the audio stack (librosa version, its default resampler): :func:`audio_stack` records
it for every result that holds beats.

Features are cached on disk (:mod:`~skeleton_mamba.tasks.motion.io.cache`) keyed by the audio file's content
and every setting; tempo and beats are re-derived from the cached beat column, so hits and misses agree.
"""

from __future__ import annotations

import inspect
import os
import re
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np
import soundfile

from skeleton_mamba.tasks.motion.io.cache import FeatureCache
from skeleton_mamba.tasks.motion.music.audio_io import probe_audio, read_audio
from skeleton_mamba.tasks.motion.music.jit_lock import librosa_calls, librosa_version

__all__ = [
    "BEAT",
    "MIN_TEMPO_SECONDS",
    "CHROMA",
    "DANCE_BPM_RANGE",
    "ENVELOPE",
    "HOP_LENGTH",
    "MFCC",
    "NUM_MUSIC_FEATURES",
    "ONSET_PEAK",
    "MusicAnalysis",
    "aist_start_bpm",
    "audio_stack",
    "beat_frames",
    "compute_music_features",
    "describe_audio_stack",
    "extract_music_features",
    "features_from_frames",
    "fold_tempo",
    "frame_features",
    "load_audio",
    "record_audio_stack",
    "tempo_from_beats",
    "tempo_octaves",
]

HOP_LENGTH = 512
NUM_MUSIC_FEATURES = 35
ENVELOPE = 0
MFCC = slice(1, 21)
CHROMA = slice(21, 33)
ONSET_PEAK = 33
BEAT = 34
DANCE_BPM_RANGE = (80.0, 170.0)
MIN_TEMPO_SECONDS = 2.0  # two beats at 60 BPM: shorter audio is too short for a tempo
TIGHTNESS = 100.0
_CACHE_VERSION = 1

_AIST_ID = re.compile(r"(?:^|_)(m(?:BR|PO|LO|MH|LH|WA|KR|JS|JB|HO)\d)(?:_|$)")


def beat_frames(features: np.ndarray) -> np.ndarray:
    """The frames (B,) whose beat flag (column :data:`BEAT`) is set, in (T, 35) music features."""
    return np.flatnonzero(np.asarray(features)[:, BEAT] > 0.5)


def aist_start_bpm(name: str) -> float | None:
    """FACT/EDGE ``start_bpm`` for an AIST music id found in ``name`` (``None`` when there is none).

    ``name`` may be the id (``"mHO5"``), a file stem (``"mHO5.wav"``) or an AIST++ sequence name
    (``"gHO_sBM_cAll_d19_mHO5_ch02"``). mBR, mPO, mLO, mMH, mLH, mWA, mKR, mJS, mJB: ``10 * digit + 80``;
    mHO: ``5 * digit + 110``.
    """
    match = _AIST_ID.search(Path(name).stem)
    if match is None:
        return None
    music_id = match.group(1)
    digit = int(music_id[3])
    return float(5 * digit + 110) if music_id.startswith("mHO") else float(10 * digit + 80)


def fold_tempo(bpm: float, bpm_range: tuple[float, float] = DANCE_BPM_RANGE) -> float:
    """Multiply or divide ``bpm`` by 2 until it lies in ``[low, high)`` (needs ``high >= 2 * low``)."""
    low, high = bpm_range
    if not (0 < low and high >= 2 * low):
        raise ValueError(f"bpm_range {bpm_range} must satisfy 0 < low and high >= 2 * low")
    if not bpm > 0:
        raise ValueError(f"tempo must be positive, got {bpm}")
    while bpm < low:
        bpm *= 2.0
    while bpm >= high:
        bpm /= 2.0
    return bpm


def tempo_from_beats(beat_frames: np.ndarray, fps: float) -> float:
    """Tempo in BPM from the least-squares slope of beat time against beat number (0.0 if < 2 beats)."""
    beats = np.asarray(beat_frames, dtype=np.float64)
    if beats.size < 2:
        return 0.0
    slope = np.polyfit(np.arange(beats.size, dtype=np.float64), beats / fps, 1)[0]
    return float(60.0 / slope)


OCTAVE_AMBIGUITY = 0.8
"""Another tempo octave at least this fraction of the detected tempo's strength makes the choice ambiguous."""


def tempo_octaves(envelope: np.ndarray, fps: float, tempo_bpm: float) -> list[tuple[float, float]]:
    """The detected tempo, half and double it (those within 30-300 BPM), each with the strength a beat
    tracker weighs it by: the onset envelope's normalised autocorrelation at that tempo's beat period (the
    best lag within 3 % of it, clipped at 0; 1 is a perfectly periodic envelope) times librosa's tempo prior
    (log-normal about 120 BPM, one octave wide, as ``librosa.feature.tempo`` weighs its tempogram). Where
    another octave is nearly as strong (:data:`OCTAVE_AMBIGUITY`), the tracker's choice between them is a
    toss-up: a 68 BPM track with busy eighth notes may be read at 136.

    Args:
        envelope: (T,) onset strength per frame (column 0 of the features).
        fps: frames per second of ``envelope``.
        tempo_bpm: the detected tempo.

    Returns:
        ``[(bpm, strength), ...]``, strongest first.

    Examples:
        >>> fps, period = 60, 30  # a pulse every 30 frames (120 BPM), every other one twice as strong
        >>> env = np.zeros(1200)
        >>> env[::period] = 1.0
        >>> env[::2 * period] = 2.0
        >>> [(bpm, round(s, 2)) for bpm, s in tempo_octaves(env, fps, 120.0)]
        [(120.0, 0.79), (60.0, 0.61), (240.0, 0.0)]
    """
    env = np.asarray(envelope, dtype=np.float64)
    env = env - env.mean()
    power = float(env @ env) / max(env.size, 1)
    out = []
    for bpm in (tempo_bpm / 2, tempo_bpm, tempo_bpm * 2):
        period = 60.0 * fps / bpm
        if not 30.0 <= bpm <= 300.0 or period < 1 or 2 * period >= env.size or power <= 0:
            continue
        lags = range(max(1, int(np.floor(0.97 * period))), int(np.ceil(1.03 * period)) + 1)
        # unbiased: each lag's products averaged over the frames it has, against the mean power per frame
        periodicity = max(float(env[:-lag] @ env[lag:]) / (env.size - lag) for lag in lags) / power
        prior = np.exp(-0.5 * np.log2(bpm / 120.0) ** 2)
        out.append((float(bpm), max(0.0, periodicity) * float(prior)))
    return sorted(out, key=lambda pair: -pair[1])


_RESAMPLER_PACKAGES = {"soxr": "soxr", "kaiser": "resampy", "fft": "scipy", "scipy": "scipy",
                       "polyphase": "scipy", "linear": "samplerate", "zero": "samplerate",
                       "sinc": "samplerate"}  # fmt: skip


def audio_stack() -> dict[str, str]:
    """The installed audio stack that decides decoded samples, features and beats, for result records.

    Keys: ``librosa``, ``numpy``, ``soundfile``, ``libsndfile`` (versions), ``resampler`` (librosa's
    ``res_type``: :func:`load_audio` and EDGE's slice round trip pass none, so it is the version's default,
    ``soxr_hq`` from librosa 0.10 on, ``kaiser_best`` (resampy) before) and ``resampler_package`` (the
    package behind it, ``"name version"``).
    """

    with librosa_calls() as librosa:
        res_type = str(inspect.signature(librosa.resample).parameters["res_type"].default)
    package = _RESAMPLER_PACKAGES.get(res_type.split("_")[0], "unknown")
    try:
        package_version = metadata.version(package)
    except metadata.PackageNotFoundError:
        package_version = "not installed"
    return {
        "librosa": librosa_version(),
        "numpy": np.__version__,
        "soundfile": soundfile.__version__,
        "libsndfile": str(soundfile.__libsndfile_version__),
        "resampler": res_type,
        "resampler_package": f"{package} {package_version}",
    }


def describe_audio_stack() -> str:
    """:func:`audio_stack` as one line for a printed table: ``"librosa 0.11.0, numpy 2.4.6, ..."``."""
    stack = audio_stack()
    libs = ", ".join(f"{name} {stack[name]}" for name in ("librosa", "numpy", "soundfile", "libsndfile"))
    return f"{libs}, resampler {stack['resampler']} ({stack['resampler_package']})"


def record_audio_stack(loggers) -> None:
    """Log :func:`audio_stack` as the hyperparameter ``audio_stack`` of every logger (a Lightning module's
    ``loggers``)."""
    stack = audio_stack()
    for logger in loggers:
        logger.log_hyperparams({"audio_stack": stack})


def load_audio(path: str | os.PathLike, sr: int, duration_s: float | None = None) -> np.ndarray:
    """Mono float32 audio resampled to ``sr``, read by the one checked reader (:func:`.audio_io.read_audio`).

    Rates, channels and duration are checked against the bounds of :mod:`.audio_io` before decoding; the
    channels are averaged (as ``librosa.to_mono``) and the result resampled with librosa's default
    resampler, as ``librosa.load(path, sr=sr)`` does. ``duration_s``: only the first seconds.

    Raises:
        FileNotFoundError: the file does not exist.
        AudioFileError: (a ``DataFileError``, so a ``ValueError``) the file cannot be decoded, is out of
            bounds, holds no samples, or a sample is NaN, Inf or out of range (the message names the file
            and the time).
    """
    y, native_sr = read_audio(path, duration_s=duration_s, mono=True)
    if native_sr == sr:
        return y
    with librosa_calls() as librosa:
        return librosa.resample(y, orig_sr=native_sr, target_sr=sr)  # as librosa.load


@dataclass
class MusicAnalysis:
    """The 35-d features of one track with its beats.

    Attributes:
        features: ``(T, 35)`` float32, one row per motion frame.
        fps: frames per second of ``features``.
        tempo_bpm: the detected tempo, from the beat times (:func:`tempo_from_beats`); ``None`` with
            fewer than two beats.
        beat_frames: ``(B,)`` frame indices of the beats (the nonzero rows of column 34).
        duration_s: length of the audio in seconds.
        tempo_note: why there is no tempo (``None`` when there is one).
    """

    features: np.ndarray
    fps: int
    tempo_bpm: float | None
    beat_frames: np.ndarray
    duration_s: float
    tempo_note: str | None = None

    @property
    def beat_times(self) -> np.ndarray:
        """``(B,)`` beat times in seconds."""
        return self.beat_frames / float(self.fps)

    @property
    def dance_tempo_bpm(self) -> float | None:
        """:attr:`tempo_bpm` folded by octaves into :data:`DANCE_BPM_RANGE` (``None`` without a tempo)."""
        return None if self.tempo_bpm is None else fold_tempo(self.tempo_bpm, DANCE_BPM_RANGE)

    @classmethod
    def from_features(cls, features: np.ndarray, fps: int, duration_s: float) -> MusicAnalysis:
        beats = beat_frames(features)
        if len(beats) >= 2:
            return cls(features, fps, tempo_from_beats(beats, fps), beats, duration_s)
        if not np.any(features[:, ENVELOPE] > 0):
            note = "the audio is silent (no onsets), so it has no tempo"
        elif duration_s < MIN_TEMPO_SECONDS:
            note = f"the audio is too short for a tempo ({duration_s:.2f} s, needs {MIN_TEMPO_SECONDS:g} s)"
        else:
            note = f"no steady beat found ({len(beats)} beat{'s' * (len(beats) != 1)} in {duration_s:.2f} s)"
        return cls(features, fps, None, beats, duration_s, note)


def compute_music_features(
    y: np.ndarray,
    fps: int = 60,
    start_bpm: float | None = None,
    tightness: float = TIGHTNESS,
    bpm_range: tuple[float, float] | None = None,
) -> MusicAnalysis:
    """The 35-d feature of mono audio ``y`` sampled at ``fps * 512`` Hz.

    Args:
        y: ``(N,)`` mono audio at ``fps * HOP_LENGTH`` Hz (see :func:`load_audio`).
        fps: motion frame rate: 60 (FACT) or 30 (EDGE); any positive integer works.
        start_bpm: beat-tracker tempo prior; ``None`` uses librosa's estimate (EDGE's fallback).
        tightness: beat-tracker tightness (100 in FACT and EDGE).
        bpm_range: fold an estimated prior into this octave first (default ``None``: as detected).

    Returns:
        A :class:`MusicAnalysis` whose ``features`` are ``(1 + N // 512, 35)``.
    """
    sr = int(fps) * HOP_LENGTH
    y = np.asarray(y, dtype=np.float32)
    envelope, mfcc, chroma = frame_features(y, sr)
    features = features_from_frames(envelope, mfcc, chroma, fps, start_bpm, tightness, bpm_range)
    return MusicAnalysis.from_features(features, int(fps), len(y) / sr)


def frame_features(y: np.ndarray, sr: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-frame parts of the feature of mono ``y`` at ``sr`` Hz (hop :data:`HOP_LENGTH`, centred):
    onset envelope ``(T,)``, 20 MFCC ``(T, 20)``, 12 CENS chroma ``(T, 12)``."""
    with librosa_calls() as librosa:  # numba compiles on first use: see jit_lock.py
        envelope = librosa.onset.onset_strength(y=y, sr=sr)  # (T,)
        mfcc = librosa.feature.mfcc(y=y, sr=sr, n_mfcc=20).T  # (T, 20)
        chroma = librosa.feature.chroma_cens(y=y, sr=sr, hop_length=HOP_LENGTH, n_chroma=12).T  # (T, 12)
    t = min(len(envelope), len(mfcc), len(chroma))  # equal for centred frames; guard anyway
    return envelope[:t], mfcc[:t], chroma[:t]


def features_from_frames(
    envelope: np.ndarray,
    mfcc: np.ndarray,
    chroma: np.ndarray,
    fps: int,
    start_bpm: float | None = None,
    tightness: float = TIGHTNESS,
    bpm_range: tuple[float, float] | None = None,
    tempogram: np.ndarray | None = None,
) -> np.ndarray:
    """The ``(T, 35)`` feature from the per-frame parts (:func:`frame_features`): the onset peaks, the tempo
    prior (when ``start_bpm`` is None) and the beats are found on the whole ``envelope``.

    ``tempogram``: the envelope's tempogram averaged over time, ``(win, 1)``, when already computed
    (:func:`~.music_windows.mean_tempogram`, in windows); librosa's tempo estimates then read it instead
    of computing the whole ``(win, T)`` tempogram.
    """
    sr = int(fps) * HOP_LENGTH
    with librosa_calls() as librosa:

        def tempo(prior: float) -> float | None:
            if tempogram is None:
                return None  # beat_track estimates it from the envelope
            found = librosa.feature.tempo(
                tg=tempogram, sr=sr, hop_length=HOP_LENGTH, start_bpm=prior, aggregate=None
            )
            return float(found[0])

        peak_idxs = librosa.onset.onset_detect(
            onset_envelope=envelope.flatten(), sr=sr, hop_length=HOP_LENGTH
        )
        if start_bpm is None:
            estimate = tempo(120.0)
            if estimate is None:
                estimate = float(
                    librosa.feature.tempo(onset_envelope=envelope, sr=sr, hop_length=HOP_LENGTH)[0]
                )
            if not estimate > 0:  # no periodicity at all (silence): librosa's default prior
                estimate = 120.0
            start_bpm = estimate if bpm_range is None else fold_tempo(estimate, bpm_range)
        _, beat_idxs = librosa.beat.beat_track(
            onset_envelope=envelope, sr=sr, hop_length=HOP_LENGTH, start_bpm=start_bpm, tightness=tightness,
            bpm=tempo(start_bpm),
        )  # fmt: skip
    peak_onehot = np.zeros_like(envelope, dtype=np.float32)
    peak_onehot[peak_idxs] = 1.0
    beat_onehot = np.zeros_like(envelope, dtype=np.float32)
    beat_onehot[beat_idxs] = 1.0
    return np.concatenate(
        [envelope[:, None], mfcc, chroma, peak_onehot[:, None], beat_onehot[:, None]], axis=-1
    ).astype(np.float32)


def extract_music_features(
    path: str | os.PathLike,
    fps: int = 60,
    start_bpm: float | None = None,
    tightness: float = TIGHTNESS,
    bpm_range: tuple[float, float] | None = None,
    cache_dir: str | os.PathLike | None = None,
    use_cache: bool = True,
    duration_s: float | None = None,
) -> MusicAnalysis:
    """Load an audio file and compute (or fetch from the cache) its 35-d features.

    A track (or its first ``duration_s`` seconds) longer than
    :data:`~.music_windows.LONG_TRACK_S` is analysed in windows (:mod:`.music_windows`): memory does
    not grow with its length.

    Args:
        path: audio file.
        fps: 60 (FACT, QEAN) or 30 (EDGE, EgoMusic).
        start_bpm: tempo prior; ``None`` uses the AIST music id in the file name if any
            (:func:`aist_start_bpm`), else librosa's estimate.
        tightness: beat-tracker tightness.
        bpm_range: fold an estimated prior into this octave (``None``, default: as detected).
        cache_dir: cache folder (default ``~/.cache/skeleton_mamba/music``).
        use_cache: ``False`` always recomputes and writes nothing.
        duration_s: analyse only the first seconds (``None``: the whole track).
    """
    from skeleton_mamba.tasks.motion.music.music_windows import (  # lazy: it imports this module
        LONG_TRACK_S,
        mean_tempogram,
        windowed_frame_features,
    )

    if fps <= 0 or int(fps) != fps:
        raise ValueError(f"fps must be a positive integer, got {fps}")
    fps = int(fps)
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: audio file not found")
    # The header's checks come first, on cache hits too (and before the cache key hashes the content).
    info = probe_audio(path)
    if start_bpm is None:
        start_bpm = aist_start_bpm(path.name)
    if duration_s is not None and not duration_s > 0:
        raise ValueError(f"duration_s must be positive, got {duration_s}")
    length_s = info.duration_s if duration_s is None else min(info.duration_s, duration_s)
    windowed = length_s > LONG_TRACK_S
    settings = {
        "kind": "fact35",
        "version": _CACHE_VERSION,
        "fps": fps,
        "start_bpm": start_bpm,
        "tightness": tightness,
        "bpm_range": None if bpm_range is None else list(bpm_range),
        "librosa": librosa_version(),
        **({} if duration_s is None else {"duration_s": float(duration_s)}),
        **({"windows": "music_windows-1"} if windowed else {}),
    }
    cache = FeatureCache("music", cache_dir, enabled=use_cache)
    key = cache.key(path, settings)
    features = cache.load(key)
    if features is None or features.ndim != 2 or features.shape[1] != NUM_MUSIC_FEATURES:
        if windowed:
            frames = windowed_frame_features(path, fps, duration_s)
            tempogram = mean_tempogram(frames[0], fps)
            features = features_from_frames(*frames, fps, start_bpm, tightness, bpm_range, tempogram)
        else:
            y = load_audio(path, fps * HOP_LENGTH, duration_s)
            features = compute_music_features(y, fps, start_bpm, tightness, bpm_range).features
        cache.store(key, features)
    # The header duration, identical on hits and misses (the decoded length can differ by a few samples).
    return MusicAnalysis.from_features(features, fps, length_s)
