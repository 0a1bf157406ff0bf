"""``sm`` deletes and replaces only what it can prove it wrote (issue 61, item 1).

An output folder is claimed only by the manifest the command signed there, checked against the sizes and
hashes it recorded: a planted, edited or foreign-keyed manifest claims nothing, nor does a file changed
since; no clean-up follows a symbolic link or leaves the output folder; ``--overwrite`` deletes nothing;
``--name`` is a plain file name; a re-export removes the files of the export it replaces, and only those.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.motion.io.output_folder import (
    MANIFEST,
    claim_output_folder,
    output_key,
    verified_outputs,
    writing_outputs,
)
from skeleton_mamba.tasks.training.cli import main as sm
from tests.helpers.motions import _motion

EGO_OPTIONS = (
    "--scenes procedural --num-rooms 1 --fps 10 --window 1 --width 16 --height 16 --workers 1 --quiet"
)


@pytest.fixture(autouse=True)
def own_key(tmp_path, monkeypatch):
    """A key of this test's own (the user's cache folder is not touched)."""
    monkeypatch.setenv("SKELETON_MAMBA_CACHE", str(tmp_path / "cache"))


def _write(out: Path, command: str, files: dict[str, bytes], **kw) -> None:
    with writing_outputs(out, command, files, **kw):
        for name, data in files.items():
            (out / name).write_bytes(data)


def _dance_args(tmp_path: Path) -> list[str]:
    """``sm dance`` with input files that exist (checked as it parses) and a checkpoint that does not."""
    (tmp_path / "m.wav").write_bytes(b"")
    (tmp_path / "v.mp4").write_bytes(b"")
    return [
        "dance",
        "--ckpt",
        "none.ckpt",
        "--music",
        str(tmp_path / "m.wav"),
        "--video",
        str(tmp_path / "v.mp4"),
    ]


def test_a_commands_own_output_is_proven_by_its_signed_manifest(tmp_path):
    out = tmp_path / "live"
    _write(out, "sm stream", {"song.npz": b"poses", "song.mp4": b"video"})
    record = json.loads((out / MANIFEST).read_text())
    assert record["files"]["song.npz"] == {"size": 5, "sha256": hashlib.sha256(b"poses").hexdigest()}
    assert set(verified_outputs(out, "sm stream")) == {"song.npz", "song.mp4"}
    assert claim_output_folder(out, "sm stream", ["song.npz"]) == out
    assert (tmp_path / "cache" / "output-key").stat().st_mode & 0o777 == 0o600
    assert len(output_key()) == 32


@pytest.mark.parametrize("how", ["planted", "edited manifest", "edited file", "another key", "a link"])
def test_a_planted_or_edited_manifest_claims_nothing(tmp_path, monkeypatch, how):
    out = tmp_path / "dances"
    out.mkdir()
    users = out / "dance.npz"
    if how == "planted":  # a manifest naming the user's file, with its true size and hash, but no signature
        users.write_bytes(b"the user's dance")
        entry = {"size": users.stat().st_size, "sha256": hashlib.sha256(users.read_bytes()).hexdigest()}
        (out / MANIFEST).write_text(json.dumps({"command": "sm dance", "files": {"dance.npz": entry}}))
    else:
        _write(out, "sm dance", {"dance.bvh": b"ours"})
        if how == "edited manifest":  # the user's file added to sm's manifest
            users.write_bytes(b"the user's dance")
            record = json.loads((out / MANIFEST).read_text())
            entry = {"size": users.stat().st_size, "sha256": hashlib.sha256(users.read_bytes()).hexdigest()}
            record["files"]["dance.npz"] = entry
            (out / MANIFEST).write_text(json.dumps(record))
        elif how == "edited file":  # the user changed sm's file since: it is theirs now
            users = out / "dance.bvh"
            users.write_bytes(b"the user's edit")
        elif how == "another key":  # a folder signed by someone else's key (copied from another machine)
            users = out / "dance.bvh"
            monkeypatch.setenv("SKELETON_MAMBA_CACHE", str(tmp_path / "other-cache"))
        else:  # sm's file replaced by a link to one of the user's files
            users = tmp_path / "photo.jpg"
            users.write_bytes(b"a photo")
            (out / "dance.bvh").unlink()
            (out / "dance.bvh").symlink_to(users)
    with pytest.raises(InputError, match="not empty and not an earlier output of sm dance"):
        claim_output_folder(out, "sm dance", ["dance.npz", "dance.bvh"])
    assert users.exists()


def test_sm_dance_does_not_replace_a_file_a_planted_manifest_names(tmp_path, capsys):
    out = tmp_path / "dances"
    out.mkdir()
    (out / "dance.npz").write_bytes(b"the user's dance")
    (out / MANIFEST).write_text(json.dumps({"command": "sm dance", "files": ["dance.npz"]}))  # the old form
    assert sm([*_dance_args(tmp_path), "--out", str(out)]) == 2
    assert "not an earlier output of sm dance" in capsys.readouterr().err
    assert (out / "dance.npz").read_bytes() == b"the user's dance"


@pytest.mark.parametrize("name", ["../victim_dance", "/tmp/victim_dance", "..", "a/b", "a\\b", ""])
@pytest.mark.parametrize("command", ["dance", "stream", "stream-recognition"])
def test_a_name_option_is_a_plain_file_name(tmp_path, capsys, name, command):
    argv = {
        "dance": _dance_args(tmp_path),
        "stream": ["stream", "--ckpt", "none.ckpt", "--music", str(tmp_path / "m.wav")],
        "stream-recognition": [
            "stream",
            "--task",
            "recognition",
            "--ckpt",
            "none.ckpt",
            "--skeleton",
            "x.npy",
        ],
    }[command]
    with pytest.raises(SystemExit) as exit_:  # argparse's refusal, before any work
        sm([*argv, "--out", str(tmp_path / "out"), "--name", name])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "argument --name" in err and "plain file name" in err, err
    assert not (tmp_path / "out").exists() and not (tmp_path / "victim_dance.npz").exists()


def test_a_re_export_removes_the_replaced_exports_files_and_only_those(tmp_path):
    out = tmp_path / "onnx"
    _write(
        out, "sm export-onnx", {"sequence.onnx": b"a", "step.onnx": b"b", "export.json": b"{}"}, replaces=True
    )
    (out / "notes.txt").write_text("the user's notes")  # written after: --overwrite is needed, kept
    claim_output_folder(out, "sm export-onnx", ["sequence.onnx"], overwrite=True)
    _write(out, "sm export-onnx", {"sequence.onnx": b"c", "export.json": b"{ }"}, replaces=True)
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "export.json", "notes.txt", "sequence.onnx"]
    assert set(verified_outputs(out, "sm export-onnx")) == {"sequence.onnx", "export.json"}
    # a block that fails removes nothing and records what it wrote
    with pytest.raises(RuntimeError), writing_outputs(out, "sm export-onnx", ["step.onnx"], replaces=True):
        (out / "step.onnx").write_bytes(b"d")
        raise RuntimeError("stopped")
    assert set(verified_outputs(out, "sm export-onnx")) == {"sequence.onnx", "export.json", "step.onnx"}


@pytest.mark.slow  # two ONNX exports: about a minute on 2 cores
def test_sm_export_onnx_re_export_leaves_only_the_new_exports_graphs(tmp_path, capsys):
    yaml = tmp_path / "b.yaml"
    yaml.write_text(
        "dim: 16\ndepth: 1\nheads: 2\nmlp_dim: 32\nmixer:\n  d_state: 8\n  headdim: 8\n  chunk_size: 16\n"
    )
    out = tmp_path / "onnx"
    base = [
        "export-onnx",
        "--backbone",
        str(yaml),
        "--skeleton",
        "ntu25",
        "--in-channels",
        "3",
        "--out",
        str(out),
    ]
    assert sm([*base, "--causal"]) == 0  # a causal backbone: the sequence and the step graphs
    first = {p.name for p in out.iterdir()}
    assert "step.onnx" in first
    assert sm(base) == 0  # a bidirectional one: no step graph
    record = json.loads((out / "export.json").read_text())
    listed = {g["file"] for g in record["graphs"].values()}
    left = {p.name for p in out.iterdir()} - {MANIFEST, "export.json"}
    assert "step.onnx" not in left and {n for n in left if n.endswith(".onnx")} == listed


def test_make_ego_follows_no_link_and_claims_no_copied_build_json(tmp_path, capsys):
    motions = tmp_path / "motions"
    _motion(motions, seconds=1.0)
    photos = tmp_path / "photos"
    (photos / "album").mkdir(parents=True)
    (photos / "album" / "a.jpg").write_bytes(b"a photo")
    out = tmp_path / "ego"
    out.mkdir()
    real = tmp_path / "real"
    assert sm(["make-ego", "--motion", str(motions), "--out", str(real), *EGO_OPTIONS.split()]) == 0
    (out / "build.json").write_bytes((real / "build.json").read_bytes())  # copied from a real build
    (out / "samples").symlink_to(photos)
    argv = ["make-ego", "--motion", str(motions), "--out", str(out), *EGO_OPTIONS.split()]
    assert sm(argv) == 2
    assert "not an earlier output of sm make-ego" in capsys.readouterr().err
    assert sm([*argv, "--overwrite"]) == 2
    assert "samples: is a symbolic link" in capsys.readouterr().err
    assert (photos / "album" / "a.jpg").read_bytes() == b"a photo"


def test_make_ego_overwrite_deletes_nothing_of_the_users(tmp_path, capsys):
    motions = tmp_path / "motions"
    _motion(motions, seconds=1.0)
    out = tmp_path / "mine"
    (out / "samples" / "my_dataset").mkdir(parents=True)
    (out / "samples" / "my_dataset" / "clip.mp4").write_bytes(b"the user's clip")
    (out / "samples" / ".tmp-x-1").mkdir()  # looks like a build's leftover, holds the user's file
    (out / "samples" / ".tmp-x-1" / "diary.txt").write_text("mine")
    argv = ["make-ego", "--motion", str(motions), "--out", str(out), *EGO_OPTIONS.split()]
    assert sm(argv) == 2
    assert sm([*argv, "--overwrite"]) == 0
    assert (out / "samples" / "my_dataset" / "clip.mp4").read_bytes() == b"the user's clip"
    assert (out / "samples" / ".tmp-x-1" / "diary.txt").read_text() == "mine"
    assert len([p for p in (out / "samples").iterdir() if (p / "COMPLETE").is_file()]) == 1
    assert sm(argv) == 2  # the user's files still there: not the build's own folder
    capsys.readouterr()
    own = ["make-ego", "--motion", str(motions), "--out", str(tmp_path / "own"), *EGO_OPTIONS.split()]
    assert sm(own) == 0
    assert sm(own) == 0  # its own build, proven by its manifest: resumed without --overwrite
    assert "1 were already complete" in capsys.readouterr().out


def test_a_build_interrupted_mid_sample_is_cleaned_inside_the_build_only(tmp_path):
    from skeleton_mamba.tasks.egodance.builder import layout

    root = tmp_path / "ego"
    leftover = root / "samples" / ".tmp-s-99"
    (leftover / "rgb").mkdir(parents=True)
    (leftover / "motion.npz").write_bytes(b"half")
    (leftover / "rgb" / "000000.png").write_bytes(b"png")
    linked = root / "samples" / ".tmp-link-1"
    os.symlink(tmp_path, linked)
    assert layout.clean_incomplete(root) == [".tmp-s-99"]
    assert linked.is_symlink() and tmp_path.is_dir()
