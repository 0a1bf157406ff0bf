"""Results that hold music beats record the audio stack that computed them (beats move with librosa)."""

from __future__ import annotations

import inspect
import json
from importlib import metadata

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.commands.analyze_music import main as analyze_main
from skeleton_mamba.tasks.motion.music.features import audio_stack
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.music import click_track

KEYS = {"librosa", "numpy", "soundfile", "libsndfile", "resampler", "resampler_package"}


def installed_stack() -> dict[str, str]:
    """The record built independently: package metadata, and the ``res_type`` default of ``librosa.load``."""
    import librosa
    import soundfile

    res_type = inspect.signature(librosa.load).parameters["res_type"].default
    package = {"soxr": "soxr", "kaiser": "resampy"}[res_type.split("_")[0]]
    return {
        "librosa": metadata.version("librosa"),
        "numpy": metadata.version("numpy"),
        "soundfile": metadata.version("soundfile"),
        "libsndfile": soundfile.__libsndfile_version__,
        "resampler": res_type,
        "resampler_package": f"{package} {metadata.version(package)}",
    }


def test_audio_stack_holds_the_installed_versions_and_resampler():
    record = audio_stack()
    assert set(record) == KEYS
    assert record == installed_stack()
    major, minor = (int(x) for x in metadata.version("librosa").split(".")[:2])
    if (major, minor) >= (0, 10):  # librosa 0.10 moved the default resampler from resampy to soxr
        assert record["resampler"] == "soxr_hq" and record["resampler_package"].startswith("soxr ")
    json.dumps(record)  # plain strings


def test_analyze_music_json_records_the_audio_stack(tmp_path, capsys):
    wav = tmp_path / "clicks.wav"
    click_track(wav)
    assert analyze_main([str(wav), "--json", "--no-cache"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["audio_stack"] == installed_stack()


@pytest.mark.parametrize("protocol", ["fact", "bailando", "edge"])
def test_evaluate_dance_json_records_the_audio_stack(folders, tmp_path, capsys, protocol):  # noqa: F811
    gen, real, music = folders
    args = ["evaluate-dance", str(gen), str(real), "--protocol", protocol, "--music-dir", str(music)]
    assert sm_main([*args, "--json", "--quiet", "--cache-dir", str(tmp_path / "cache")]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["audio_stack"] == installed_stack()
    assert np.isfinite(result["BeatAlign"])
