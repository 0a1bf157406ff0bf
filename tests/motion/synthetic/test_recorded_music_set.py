"""The recorded-music demo set (issue 58, item 2): real recordings, SYNTHETIC dances on their tracked beats.

Its builder must place the dance's kinematic beats on the recording's beats as librosa tracks them, far above
the same dance scored against the beat grid shifted by a fraction of a beat (chance), keep the unheard songs
out of the set, and write the fixed split.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip(
    "immich_memories_music",
    reason="the recorded-music set needs immich-memories-music (pip install -e .[tasks])",
)

from skeleton_mamba.tasks.motion.formats.aistpp import load_aistpp_motion  # noqa: E402
from skeleton_mamba.tasks.motion.formats.fact_features import features_to_joints, motion_to_features  # noqa: E402
from skeleton_mamba.tasks.motion.metrics.beat_align import beat_align_over_chance, kinematic_beats  # noqa: E402
from skeleton_mamba.tasks.motion.music.features import load_audio  # noqa: E402
from skeleton_mamba.tasks.motion.synthetic import recorded_music_set as recorded  # noqa: E402


@pytest.fixture(scope="module")
def demo_set(tmp_path_factory):
    root = tmp_path_factory.mktemp("recorded")
    names = recorded.write_recorded_music_aistpp(root, train_count=1, duration_s=12.0)
    return root, names


def test_the_dance_stops_on_the_recordings_tracked_beats(demo_set):
    root, names = demo_set
    for name in names:
        motion = load_aistpp_motion(root / "motions" / f"{name}.pkl")  # 60 fps, as AIST++ stores it
        joints = features_to_joints(torch.as_tensor(motion_to_features(motion, 30.0))).numpy()
        audio = load_audio(root / "music" / f"{name.split('_')[4]}.wav", recorded.SR)
        beats = recorded.tracked_beats(audio)
        # the last 2 s aside: re-tracked on the written excerpt, the last beats may differ from the builder's
        beats = beats[beats < len(joints) - 60]
        assert len(beats) >= 9, name  # 10 s of music at 60 BPM or faster
        # re-tracked on the written excerpt (resampled, 16-bit): a beat may move by a frame
        align, chance = beat_align_over_chance(joints, beats, "bailando", 30)
        assert align > 0.8 and align - chance > 0.5, (name, align, chance)
        stops = kinematic_beats(joints, "bailando", 30)
        near = np.abs(beats[:, None] - stops[None]).min(axis=1)
        assert np.mean(near <= 1) >= 0.9, (name, near)  # the stops fall within a frame of the beats


def test_the_split_is_fixed_and_the_unheard_songs_stay_out(demo_set):
    root, names = demo_set
    train = (root / "splits" / "crossmodal_train.txt").read_text().split()
    val = (root / "splits" / "crossmodal_val.txt").read_text().split()
    assert train == names[:1] and val == names[1:] and len(val) == len(recorded.TEST_TRACKS)
    sources = (root / "SYNTHETIC.txt").read_text()
    assert "MIT" in sources and all(track in sources for track in recorded.TEST_TRACKS)
    assert not any(track in sources for track in recorded.UNHEARD_TRACKS)
    training = recorded.training_tracks()
    assert not {*recorded.TEST_TRACKS, *recorded.UNHEARD_TRACKS} & set(training)
    assert len(training) + len(recorded.TEST_TRACKS) + len(recorded.UNHEARD_TRACKS) == len(
        recorded.package_tracks()
    )
    with pytest.raises(ValueError, match="train_count"):
        recorded.write_recorded_music_aistpp(root / "again", train_count=len(training) + 1)


def test_sections_change_the_style_and_keep_the_stops_on_the_beats():
    """A quiet half then a loud half (noise bursts at 113 BPM, 24 dB apart): a new section (style) at the
    change, the loud half danced wider, and the stops still on the beats through the change."""
    frames = 600
    audio = np.zeros(frames * recorded.HOP, dtype=np.float32)
    period = round(recorded.SR * 60 / 113)  # 113 BPM
    rng = np.random.default_rng(0)
    hit = rng.standard_normal(period) * np.exp(
        -np.arange(period) / (0.1 * recorded.SR)
    )  # a decaying noise burst
    for start in range(0, len(audio) - period + 1, period):
        audio[start : start + period] += (0.05 if start < len(audio) // 2 else 0.8) * hit
    piece = recorded.choreograph(audio, frames)
    assert len(piece.sections) >= 2 and piece.styles[0] != piece.styles[1]
    change = piece.sections[1]
    assert piece.amplitude[change + 4 :].mean() > piece.amplitude[: change - 4].mean() + 0.2
    joints = features_to_joints(torch.as_tensor(motion_to_features(piece.motion, 30.0))).numpy()
    speed = np.linalg.norm(np.diff(joints, axis=0), axis=-1).mean(axis=1)  # speed[t]: frame t to t + 1
    for start, beat in zip(piece.beats[:-1], piece.beats[1:], strict=True):  # every joint still on each beat
        assert min(speed[beat - 1], speed[beat]) < 0.3 * speed[start:beat].max(), beat
