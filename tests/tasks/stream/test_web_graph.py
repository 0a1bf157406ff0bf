"""The web dancer's ONNX graph (audio in, pose out) against the Python streaming path.

On the real sample tracks of ``../shared/data/music`` (each resampled to 15360 Hz mono, written as a 16-bit
WAV): the graph's features equal :func:`~skeleton_mamba.tasks.stream.features.music_features` within 1e-3
of each feature's range over the track, and the graph's poses, stepped over the whole track with
onnxruntime as the page steps them, equal ``sm stream``'s on the same WAV within 1 mm (joints).
"""

from __future__ import annotations

import numpy as np
import pytest
import soundfile as sf
import torch

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.motion.formats.fact_features import nearest_rotation
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.music.features import load_audio
from skeleton_mamba.tasks.stream.features import SR, music_features
from skeleton_mamba.tasks.stream.model import tokens_to_motion
from skeleton_mamba.tasks.stream.ort_web import VERSION, read_ort_web
from skeleton_mamba.tasks.stream.web_export import export_web_graph
from skeleton_mamba.tasks.stream.web_graph import nearest_rotation_graph, polar_rotation, run_web_graph
from skeleton_mamba.tasks.training.cli import main as sm
from tests.helpers.checkpoint_files import save_module_checkpoint, tiny_stream_checkpoint
from tests.helpers.repo import SHARED_DATA

TRACKS = sorted((SHARED_DATA / "music").glob("*.opus")) if (SHARED_DATA / "music").is_dir() else []
FEATURE_TOLERANCE = 1e-3  # of each feature's range over the track
JOINT_TOLERANCE_M = 1e-3


def test_nearest_rotation_graph_equals_the_svd_projection():
    matrices = torch.randn(4000, 3, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    assert (torch.det(matrices) < 0).sum() > 1000  # both signs
    expected = nearest_rotation(matrices)
    torch.testing.assert_close(nearest_rotation_graph(matrices), expected, rtol=0, atol=1e-6)
    positive = torch.det(matrices) > 0  # there the polar factor is the nearest rotation
    torch.testing.assert_close(polar_rotation(matrices[positive]), expected[positive], rtol=0, atol=1e-10)
    # float32 as in the graph, on noisy rotations as a dancer predicts them, reflected ones too (whose two
    # smallest singular values are close: the flipped direction is then as ill-conditioned as for an SVD)
    noisy = torch.linalg.matrix_exp(matrices - matrices.mT) + 0.1 * matrices
    noisy[::2, 0] *= -1
    error = (nearest_rotation_graph(noisy.float()).double() - nearest_rotation(noisy)).abs().max()
    assert error < 2e-4, error


def write_sr_wav(track, path):
    """The track as mono 16-bit PCM at SR (what both paths then read) and its samples as read back."""
    sf.write(path, load_audio(track, SR), SR, subtype="PCM_16")
    return sf.read(path, dtype="float32")[0]


@pytest.fixture(scope="module")
def dancer_graph(tmp_path_factory):
    """A tiny causal dancer (random weights, music statistics of a real track, the demo's low-pass) as a
    checkpoint and its exported web graph."""
    if not TRACKS:
        pytest.skip(f"real sample music not found under {SHARED_DATA / 'music'}")
    tmp = tmp_path_factory.mktemp("web_graph")
    music = torch.from_numpy(music_features(load_audio(TRACKS[0], SR), SR))
    ckpt, dancer = tiny_stream_checkpoint(tmp / "dancer.ckpt", music)
    graph = tmp / "dancer.onnx"
    _, check = export_web_graph(dancer, graph)
    assert check < 1e-3  # onnxruntime vs eager on the example inputs (random states)
    return ckpt, dancer, graph


@pytest.mark.parametrize("track", TRACKS, ids=[t.stem for t in TRACKS])
def test_web_graph_equals_the_python_features_and_sm_stream(dancer_graph, track, tmp_path):
    ckpt, dancer, graph = dancer_graph
    wav = tmp_path / f"{track.stem}.wav"
    audio = write_sr_wav(track, wav)
    ours = run_web_graph(graph, dancer, audio)

    reference = music_features(audio, SR)
    assert ours["features"].shape == reference.shape and len(reference) > 900  # 30 s at 30 fps
    scale = np.maximum(reference.max(0) - reference.min(0), 1e-6)
    relative = np.abs(ours["features"] - reference) / scale
    assert relative.max() < FEATURE_TOLERANCE, relative.max(0)

    out = tmp_path / "streamed"
    assert sm(["stream", "--ckpt", str(ckpt), "--music", str(wav), "--out", str(out), "--no-render"]) == 0
    streamed = load_motion(out / f"{track.stem}.npz")
    assert streamed.num_frames == len(ours["pose"])
    decoded = tokens_to_motion(torch.from_numpy(ours["pose"])).joints
    assert np.abs(decoded - streamed.joints).max() < JOINT_TOLERANCE_M
    assert np.abs(ours["joints"] - streamed.joints).max() < JOINT_TOLERANCE_M  # the graph's own joints


def test_the_onnxruntime_web_tarball_is_checked(tmp_path):
    with pytest.raises(InputError, match=f"{tmp_path / 'missing.tgz'}: no such file"):
        read_ort_web(tmp_path / "missing.tgz")
    other = tmp_path / "onnxruntime-web-1.31.1.tgz"
    other.write_bytes(b"not the release")
    with pytest.raises(InputError, match=f"{other}: not the npm tarball of onnxruntime-web {VERSION}"):
        read_ort_web(other)


def test_a_huge_or_forged_onnxruntime_web_tarball_is_refused_without_reading_it_whole(tmp_path, monkeypatch):
    from skeleton_mamba.tasks.stream import npm_tarball, ort_web

    huge = tmp_path / "huge.tgz"
    with huge.open("wb") as f:  # a sparse 5 GB file: refused by its size, before a byte is read
        f.truncate(5 << 30)
    opened = []
    monkeypatch.setattr(npm_tarball, "_read_hashed", lambda path, limit, chunk=0: opened.append(path))
    with pytest.raises(InputError, match=rf"huge.tgz: not the npm tarball .*\({5 << 30} bytes, not "):
        read_ort_web(huge)
    assert opened == []
    monkeypatch.undo()
    forged = tmp_path / "forged.tgz"
    with forged.open("wb") as f:  # the right size, other bytes: hashed as it is read, then refused
        f.truncate(ort_web.TARBALL_BYTES)
    with pytest.raises(InputError, match="forged.tgz: not the npm tarball .*SHA-512 differs"):
        read_ort_web(forged)


def test_a_dancer_trained_with_the_beat_phase_is_refused_in_one_line_before_anything_is_written(
    tmp_path, capsys
):
    """The page computes the 34 features only: ``sm export-web`` says so, naming the checkpoint, exit 2."""
    from skeleton_mamba.tasks.stream.module import StreamDanceModule

    tiny = {"dim": 16, "depth": 1, "heads": 2, "mlp_dim": 32, "mixer": {"d_state": 16, "headdim": 8}}
    module = StreamDanceModule(backbone={**tiny, "causal": True}, music_dim=36)
    ckpt = save_module_checkpoint(module, tmp_path / "phase.ckpt")
    out = tmp_path / "site"
    assert sm(["export-web", "--ckpt", str(ckpt), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(ckpt) in err and "beat_phase false" in err, err
    assert not (out / "index.html").exists()
