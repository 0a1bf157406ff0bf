"""An AIST++-layout demo set on REAL recordings, with SYNTHETIC dances choreographed to their beats.

The music is the MIT-licensed ``immich-memories-music`` package (28 generated instrumental tracks of about
30 s, Opus, ``immich_memories_music/tracks/<mood>/<name>.opus``; ``pip install immich-memories-music``). For
every track the dance is the toolkit's procedural dance (:func:`.dance.phase_dance`) on the recording's own
beats and sections:

* beats: librosa's beat tracker at 30 fps (:func:`tracked_beats`); the beat phase is linear between
  consecutive tracked beats (extrapolated with the first and last beat period), so every joint stops on
  every tracked beat whatever the tempo's drift;
* sections: the track's loudness per beat (RMS, dB) averaged over two bars. Where the mean of the next two
  bars differs from the previous two by more than :data:`SECTION_DB` dB on a bar line, a new section starts
  and the dance turns to the next style; the amplitude follows the loudness about the track's median,
  within :data:`AMPLITUDE_RANGE` (its ends at two such steps, +-3 dB). Both change with a half-cosine ease
  over one beat whose slope is zero on the beats, so the stops stay on the beats.

The split is fixed (:data:`TEST_TRACKS`, :data:`UNHEARD_TRACKS`): the test tracks are the demo's held-out
(``val``) songs; the unheard tracks are never written into the set, so a model trained on it has never heard
them (``benchmarks/bench_conditioning.py`` dances to them); every other track may train. Written as
:mod:`.aistpp_set` writes the drum-track set: ``<root>/motions/<name>.pkl`` (60 fps SMPL),
``<root>/music/<music id>.wav`` (the decoded excerpt), ``<root>/splits/crossmodal_{train,val}.txt``, and
``SYNTHETIC.txt`` naming the source track of every music id and its licence.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import soundfile as sf

from skeleton_mamba.io.atomic import atomic_open, atomic_path
from skeleton_mamba.tasks.motion.formats.aistpp import music_id
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.motion.music.features import load_audio
from skeleton_mamba.tasks.motion.music.jit_lock import librosa_calls
from skeleton_mamba.tasks.motion.synthetic.aistpp_set import GENRES, SCALING
from skeleton_mamba.tasks.motion.synthetic.dance import STYLES, dance_motion, phase_dance

__all__ = [
    "AMPLITUDE_RANGE",
    "ANALYSIS_S",
    "LABEL",
    "PACKAGE",
    "SECTION_DB",
    "TEST_TRACKS",
    "UNHEARD_TRACKS",
    "Choreography",
    "choreograph",
    "package_tracks",
    "tracked_beats",
    "training_tracks",
    "write_recorded_music_aistpp",
]

PACKAGE = "immich-memories-music"
LABEL = (
    "SYNTHETIC dances choreographed to REAL recordings (immich-memories-music, MIT): procedural dances on "
    "each recording's tracked beats and sections"
)
# The demo's held-out (val) songs: two moods and tempi (110 and 99 BPM by the package's list).
TEST_TRACKS = ("happy_acoustic_s411", "tender_electronic_1")
# Never written into the set: the three of the shared music folder, and two more (132 and 84 BPM).
UNHEARD_TRACKS = (
    "energetic_acoustic_1",
    "energetic_electronic_2",
    "happy_electronic_1",
    "energetic_acoustic_2",
    "nostalgic_electronic_s411",
)
FPS = 30
HOP = 512
SR = FPS * HOP  # one hop is one 30 fps frame (the live dancer's feature rate)
WAV_RATE = 22050  # the written excerpts
ANALYSIS_S = 12.0  # the least music whose beats and sections are tracked for an excerpt
SECTION_DB = 1.5
AMPLITUDE_RANGE = (0.75, 1.15)
BEATS_PER_BAR = 4


def package_tracks() -> dict[str, Path]:
    """``{track name: .opus path}`` of every track of the installed ``immich-memories-music``.

    Raises:
        ModuleNotFoundError: the package is not installed (the message says how to install it).
    """
    try:
        import immich_memories_music  # lazy: an optional dependency of the stream task, checked here
    except ModuleNotFoundError as err:
        raise ModuleNotFoundError(
            f"the recorded-music demo set needs the {PACKAGE} package: pip install {PACKAGE} "
            '(or pip install -e ".[tasks]")'
        ) from err
    tracks = {p.stem: p for p in sorted(immich_memories_music.tracks_dir().glob("*/*.opus"))}
    missing = [name for name in (*TEST_TRACKS, *UNHEARD_TRACKS) if name not in tracks]
    if missing:
        raise FileNotFoundError(
            f"{immich_memories_music.tracks_dir()}: tracks {missing} of the split missing"
        )
    return tracks


def training_tracks() -> list[str]:
    """The tracks the set may train on: every package track but the test and unheard ones, sorted."""
    held = {*TEST_TRACKS, *UNHEARD_TRACKS}
    return [name for name in package_tracks() if name not in held]


def tracked_beats(audio: np.ndarray) -> np.ndarray:
    """Beat frames at 30 fps of mono audio at :data:`SR` (librosa's beat tracker, hop = one frame)."""
    with librosa_calls() as librosa:
        _, beats = librosa.beat.beat_track(y=audio, sr=SR, hop_length=HOP)
    return np.asarray(beats, dtype=np.int64)


def _phase(beats: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Beat phase at ``frames`` (30 fps frame units, (T,)): ``k`` on the k-th tracked beat, linear between
    beats, extrapolated at both ends."""
    phi = np.interp(frames, beats, np.arange(len(beats), dtype=np.float64))
    first, last = beats[1] - beats[0], beats[-1] - beats[-2]
    phi[frames < beats[0]] = (frames[frames < beats[0]] - beats[0]) / first
    after = frames > beats[-1]
    phi[after] = len(beats) - 1 + (frames[after] - beats[-1]) / last
    return phi


def _eased(values: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Per-beat values (K,) -> per-frame (T, ...): ``values[k]`` on beat k, a half-cosine between beats (zero
    slope on every beat); constant before the first beat and after the last."""
    k = np.clip(np.floor(phi), 0, len(values) - 1).astype(np.int64)
    nxt = np.minimum(k + 1, len(values) - 1)
    frac = np.clip(phi - np.floor(phi), 0.0, 1.0)
    frac = np.where(phi < 0, 0.0, frac)
    ease = ((1 - np.cos(np.pi * frac)) / 2).reshape(-1, *([1] * (values.ndim - 1)))
    return values[k] * (1 - ease) + values[nxt] * ease


@dataclass(frozen=True)
class Choreography:
    """A dance on a recording. ``motion``: SMPL at 30 fps; ``beats``: the tracked beat frames; ``sections``:
    the beats on which a section starts (the first is 0); ``styles``: each section's style; ``amplitude``:
    the per-beat amplitude."""

    motion: MotionData
    beats: np.ndarray
    sections: list[int]
    styles: list[str]
    amplitude: np.ndarray


def choreograph(
    audio: np.ndarray, num_frames: int, seed: int = 0, first_style: int = 0, fps: float = FPS
) -> Choreography:
    """The dance (module docstring) of ``num_frames`` 30 fps frames on mono ``audio`` at :data:`SR`, sampled
    at ``fps`` (its ``motion``; the beats stay in 30 fps frames). ``first_style``: the first section's style
    (index into the sorted styles, which later sections cycle through).

    Raises:
        ValueError: fewer than 4 beats tracked.
    """
    beats = tracked_beats(audio)
    beats = beats[beats < num_frames]
    if len(beats) < 4:
        raise ValueError(f"only {len(beats)} beats tracked in {num_frames} frames: too short to choreograph")
    with librosa_calls() as librosa:
        rms = librosa.feature.rms(y=audio, frame_length=2 * HOP, hop_length=HOP)[0]
    loud = 20 * np.log10(rms + 1e-5)
    edges = np.append(beats, num_frames)
    per_beat = np.array([loud[a : max(a + 1, b)].mean() for a, b in zip(edges[:-1], edges[1:])])
    two_bars = 2 * BEATS_PER_BAR
    sections = [0]
    for k in range(two_bars, len(beats) - two_bars + 1, BEATS_PER_BAR):
        change = abs(per_beat[k : k + two_bars].mean() - per_beat[k - two_bars : k].mean())
        if change > SECTION_DB and k - sections[-1] >= two_bars:
            sections.append(k)
    styles_cycle = sorted(STYLES)
    section_of_beat = np.searchsorted(sections, np.arange(len(beats)), side="right") - 1
    styles = [styles_cycle[(first_style + i) % len(styles_cycle)] for i in range(len(sections))]
    kernel = np.ones(two_bars) / two_bars
    smooth = np.convolve(
        np.pad(per_beat, (two_bars // 2, two_bars - 1 - two_bars // 2), mode="edge"), kernel, "valid"
    )
    low, high = AMPLITUDE_RANGE
    swing = np.clip((smooth - np.median(smooth)) / (2 * SECTION_DB), -1.0, 1.0)  # +-2 sections' steps
    amplitude = (low + high) / 2 + (high - low) / 2 * swing
    phi = _phase(beats, np.arange(round(num_frames * fps / FPS)) * FPS / fps)
    gain = _eased(amplitude, phi)
    weights = _eased(np.eye(len(styles_cycle))[[styles_cycle.index(styles[s]) for s in section_of_beat]], phi)
    euler = np.zeros((len(phi), 24, 3))
    trans = np.zeros((len(phi), 3))
    for i, style in enumerate(styles_cycle):
        if weights[:, i].any():
            e, t = phase_dance(phi, style, seed, amplitude=gain)
            euler += weights[:, i, None, None] * e
            trans += weights[:, i, None] * t
    return Choreography(dance_motion(euler, trans, float(fps)), beats, sections, styles, amplitude)


def _write_pair(
    root: Path, name: str, audio: np.ndarray, samples: int, seed: int, first_style: int
) -> Choreography:
    """Choreograph all of ``audio``; write its first ``samples`` (the music) and their frames (the dance)."""
    frames = samples // HOP
    piece = choreograph(audio, len(audio) // HOP, seed, first_style, fps=60.0)  # 60 fps, as AIST++ stores it
    motion = piece.motion
    data = {
        "smpl_poses": motion.poses[: 2 * frames].reshape(-1, 72).astype(np.float32),
        "smpl_trans": (motion.trans[: 2 * frames] * SCALING).astype(np.float32),
        "smpl_scaling": np.array([SCALING], dtype=np.float32),
    }
    with atomic_open(root / "motions" / f"{name}.pkl", "wb") as f:
        pickle.dump(data, f)
    with librosa_calls() as librosa:
        wav = librosa.resample(audio[:samples], orig_sr=SR, target_sr=WAV_RATE)
    with atomic_path(root / "music" / f"{music_id(name)}.wav") as tmp:
        sf.write(tmp, wav, WAV_RATE, subtype="PCM_16")
    return piece


def write_recorded_music_aistpp(
    root: str | Path, train_count: int = 12, duration_s: float = 30.0, seed: int = 0
) -> list[str]:
    """Write the first ``train_count`` training tracks (:func:`training_tracks`) and the :data:`TEST_TRACKS`
    (the ``val`` split) with their dances under ``root`` (module docstring); returns the names, val last.
    ``duration_s``: the excerpt of each track (from its start); its beats and sections are found on at least
    the first :data:`ANALYSIS_S` seconds (a few seconds hold too few beats to track).

    Raises:
        ValueError: ``train_count`` outside 1 ... the number of training tracks.
        ModuleNotFoundError: ``immich-memories-music`` is not installed.
    """
    tracks = package_tracks()
    train = training_tracks()
    if not 1 <= train_count <= len(train):
        raise ValueError(
            f"train_count must be in 1 ... {len(train)} (the training tracks), got {train_count}"
        )
    root = Path(root)
    for folder in ("motions", "music", "splits"):
        (root / folder).mkdir(parents=True, exist_ok=True)
    chosen = [*train[:train_count], *TEST_TRACKS]
    names, sources = [], []
    for k, track in enumerate(chosen):
        genre, index = GENRES[k % len(GENRES)], k // len(GENRES)
        name = f"g{genre}_sBM_cAll_d{k:02d}_m{genre}{index}_ch01"
        audio = load_audio(tracks[track], SR, max(duration_s, ANALYSIS_S))
        piece = _write_pair(root, name, audio, min(len(audio), round(duration_s * SR)), seed + k, k)
        names.append(name)
        sources.append(f"{music_id(name)}\t{track}\t{'+'.join(piece.styles)}\t{len(piece.beats)} beats")
    train_names, val_names = names[:train_count], names[train_count:]
    (root / "splits" / "crossmodal_train.txt").write_text("\n".join(train_names) + "\n", encoding="utf-8")
    (root / "splits" / "crossmodal_val.txt").write_text("\n".join(val_names) + "\n", encoding="utf-8")
    (root / "SYNTHETIC.txt").write_text(
        f"{LABEL}.\nMusic: the {PACKAGE} package (MIT licence, generated with ACE-Step), decoded excerpts of "
        f"{duration_s:g} s.\nmusic id\tsource track\tstyles by section\tbeats\n" + "\n".join(sources) + "\n",
        encoding="utf-8",
    )
    return names
