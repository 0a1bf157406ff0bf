"""No file of the user's replaced without being asked (issue 43).

Every command writing into a folder (``sm export-pretrained``, ``export-onnx``, ``dance``, ``stream``,
``generate``, ``make-ego``) refuses, before any work, a non-empty folder that is not its own earlier output
(proven by the signed manifest it wrote: ``test_output_proof.py``), unless ``--overwrite``; files
beside a named output (``sm dance --out FILE.npz``, ``sm export --music``) are not replaced unasked; every
file is written atomically with the mode the umask gives.
"""

from __future__ import annotations

import os
from pathlib import Path

import lightning
import numpy as np
import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.errors import InputError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.tasks.motion.io.output_folder import MANIFEST, claim_output_folder, writing_outputs
from skeleton_mamba.tasks.training.cli import main as sm

MIXER = MixerConfig(d_state=8, headdim=8, chunk_size=16)
TINY = SkeletonMambaConfig(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MIXER)


@pytest.fixture
def user_folder(tmp_path):
    """A folder of the user's: a README and a config.json that must survive every command."""
    folder = tmp_path / "project"
    folder.mkdir()
    (folder / "README.md").write_text("# my project\n")
    (folder / "config.json").write_text('{"mine": true}\n')
    return folder


def _untouched(folder) -> None:
    assert (folder / "README.md").read_text() == "# my project\n"
    assert (folder / "config.json").read_text() == '{"mine": true}\n'


@pytest.fixture
def stream_ckpt(tmp_path):
    from skeleton_mamba.tasks.stream.module import StreamDanceModule

    torch.manual_seed(0)
    module = StreamDanceModule(backbone=TINY)
    hparams = {**dict(module.hparams), "_class_path": "skeleton_mamba.tasks.stream.module.StreamDanceModule"}
    path = tmp_path / "stream.ckpt"
    torch.save({"state_dict": module.state_dict(), "hyper_parameters": hparams,
                "pytorch-lightning_version": lightning.__version__}, path)  # fmt: skip
    return path


def _refused(capsys, args: list[str], folder) -> str:
    assert sm(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(folder) in err, err
    assert "not empty and not an earlier output" in err or "would be replaced" in err, err
    return err


def test_export_pretrained_never_replaces_the_users_readme(user_folder, stream_ckpt, capsys, monkeypatch):
    args = ["export-pretrained", "--ckpt", str(stream_ckpt), "--out"]
    err = _refused(capsys, [*args, str(user_folder)], user_folder)
    assert "'README.md'" in err or "'config.json'" in err
    monkeypatch.chdir(user_folder)  # `--out .` inside a project
    _refused(capsys, [*args, "."], ".")
    _untouched(user_folder)
    assert sorted(p.name for p in user_folder.iterdir()) == ["README.md", "config.json"]


def test_export_pretrained_takes_its_own_folder_again_and_overwrites_only_when_asked(
    tmp_path, stream_ckpt, capsys
):
    out = tmp_path / "dancer"
    args = ["export-pretrained", "--ckpt", str(stream_ckpt), "--out", str(out)]
    assert sm(args) == 0
    first = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert sm(args) == 0  # its own earlier output: the same four files and nothing else, written again
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()}.keys() == first.keys()
    (out / "notes.txt").write_text("mine")
    err = _refused(capsys, args, out)
    assert "'notes.txt'" in err
    assert sm([*args, "--overwrite"]) == 0
    assert (out / "notes.txt").read_text() == "mine"  # --overwrite replaces its own names, deletes nothing


def test_export_onnx_refuses_a_users_folder_before_any_work(user_folder, capsys, tmp_path):
    (tmp_path / "b.yaml").write_text("dim: 16\ndepth: 1\n")
    args = [
        "export-onnx",
        "--backbone",
        str(tmp_path / "b.yaml"),
        "--skeleton",
        "ntu25",
        "--in-channels",
        "3",
    ]
    _refused(capsys, [*args, "--out", str(user_folder)], user_folder)
    _untouched(user_folder)
    onnx = tmp_path / "onnx"
    onnx.mkdir()
    (onnx / "export.json").write_text("{}")  # looks like an export, but no manifest proves it
    (onnx / "sequence.onnx").write_bytes(b"old")
    with pytest.raises(InputError, match="not an earlier output of sm export-onnx"):
        claim_output_folder(onnx, "sm export-onnx", ["sequence.onnx", "export.json"])


def test_sm_dance_never_replaces_a_file_beside_its_named_output(tmp_path, capsys):
    video = tmp_path / "take.mp4"
    video.write_bytes(b"the user's own video")
    (tmp_path / "m.wav").write_bytes(b"")  # sm dance's inputs must exist: they are checked as it parses
    args = ["dance", "--ckpt", str(tmp_path / "none.ckpt"), "--music", str(tmp_path / "m.wav")]
    args += ["--video", str(video)]
    err = _refused(capsys, [*args, "--out", str(tmp_path / "take.npz")], video)
    assert "written beside" in err
    assert video.read_bytes() == b"the user's own video"


@pytest.mark.parametrize(
    "command",
    [
        ["dance", "--ckpt", "none.ckpt", "--music", "INPUT/m.wav", "--video", "INPUT/v.mp4"],
        ["stream", "--ckpt", "CKPT", "--music", "song.wav"],
        ["stream", "--task", "recognition", "--ckpt", "CKPT", "--skeleton", "clip.npy"],
        ["generate", "--checkpoint", "none.ckpt", "--text", "a person walks"],
        ["make-ego", "--motion", "motions", "--scenes", "procedural"],
    ],
    ids=["dance", "stream", "stream-recognition", "generate", "make-ego"],
)
def test_every_folder_command_refuses_a_users_folder_before_any_work(
    user_folder, stream_ckpt, capsys, command
):
    command = [str(stream_ckpt) if arg == "CKPT" else arg for arg in command]  # checked to exist first
    for i, arg in enumerate(command):  # input files that exist (sm dance checks them as it parses)
        if arg.startswith("INPUT/"):
            command[i] = str(user_folder.parent / arg.removeprefix("INPUT/"))
            Path(command[i]).write_bytes(b"")
    _refused(capsys, [*command, "--out", str(user_folder)], user_folder)
    _untouched(user_folder)
    assert not (user_folder / MANIFEST).exists()


def test_sm_export_does_not_replace_a_wav_beside_the_glb(tmp_path, capsys):
    from skeleton_mamba.tasks.motion.formats.motion_file import save_motion
    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music
    from tests.helpers.motions import _smpl_motion

    save_motion(tmp_path / "m.npz", _smpl_motion(4))
    song = write_music(tmp_path / "song.wav", synthesize_music(120.0, 1.0, sr=22050, seed=1))
    (tmp_path / "out.wav").write_bytes(b"the user's recording")
    args = ["export", str(tmp_path / "m.npz"), "--out", str(tmp_path / "out.glb"), "--music", str(song)]
    _refused(capsys, args, tmp_path / "out.wav")
    assert (tmp_path / "out.wav").read_bytes() == b"the user's recording"
    assert not (tmp_path / "out.glb").exists()
    assert sm([*args, "--overwrite"]) == 0 and (tmp_path / "out.wav").read_bytes()[:4] == b"RIFF"


def test_the_manifest_recognises_a_commands_own_files_only(tmp_path):
    out = tmp_path / "live"
    claim_output_folder(out, "sm stream", ["song.npz"])
    assert not out.exists()  # claiming creates nothing: recording does, before the first file
    with writing_outputs(out, "sm stream", ["song.npz", "song.bvh"]):
        (out / "song.npz").write_bytes(b"1")
    claim_output_folder(out, "sm stream", ["other.npz"])  # its own earlier output
    with writing_outputs(out, "sm stream", ["other.npz"]):
        pass
    with pytest.raises(InputError, match="not an earlier output of sm dance"):
        claim_output_folder(out, "sm dance", ["dance.npz"])  # another command's folder
    (out / "photo.jpg").write_bytes(b"2")
    with pytest.raises(
        InputError, match=r"live: not empty and not an earlier output of sm stream .*'photo.jpg'"
    ):
        claim_output_folder(out, "sm stream", ["song.npz"])
    assert claim_output_folder(out, "sm stream", ["song.npz"], overwrite=True) == out
    with pytest.raises(InputError, match="is a file"):
        claim_output_folder(out / "photo.jpg", "sm stream", ["x"])


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_atomic_files_get_the_mode_the_umask_gives(tmp_path, umask):
    previous = os.umask(umask)
    try:
        with atomic_open(tmp_path / "f.txt", "w") as f:
            f.write("x")
    finally:
        os.umask(previous)
    assert (tmp_path / "f.txt").stat().st_mode & 0o777 == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == ["f.txt"]  # no temporary file left


def test_an_interrupted_write_keeps_the_old_file(tmp_path):
    (tmp_path / "f.npy").write_bytes(b"old")
    with pytest.raises(KeyboardInterrupt), atomic_open(tmp_path / "f.npy", "wb") as f:
        np.save(f, np.zeros(3))
        raise KeyboardInterrupt
    assert (tmp_path / "f.npy").read_bytes() == b"old" and len(list(tmp_path.iterdir())) == 1
