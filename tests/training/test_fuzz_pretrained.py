"""Hostile pretrained folders and checkpoints (issue 43): checked before anything is allocated.

A folder's ``config.json`` sizes are bounded, the network is built on the ``meta`` device and compared with
the safetensors header (parsed here, bounded) before a tensor is read, and the tensors are finite and of
the network's types. The commands (``sm export-onnx --pretrained``, ``sm stream --ckpt FOLDER``) run under
an address-space limit, so a size that got through would fail by running out of memory, not pass slowly.
"""

from __future__ import annotations

import json
import math
import os
import resource
import struct
import subprocess
import time
import warnings
from pathlib import Path

import lightning
import pytest
import torch
from safetensors.torch import save_file

from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.errors import CheckpointError
from skeleton_mamba.pretrained.checks import MAX_PARAMETERS, MAX_TENSORS, meta_state, read_safetensors_header
from skeleton_mamba.pretrained.mixin import CONFIG_NAME, WEIGHTS_NAME, PretrainedError
from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music
from skeleton_mamba.tasks.training.checkpoints import load_checkpoint
from skeleton_mamba.tasks.training.cli import main as sm
from tests.helpers.sm import sm_executable
from tests.training.networks import _networks

MEMORY_LIMIT = 3 << 30  # address space of the `sm` subprocesses (the hostile sizes need tens of GB)
MIXER = MixerConfig(d_state=8, headdim=8, chunk_size=16)
TINY = SkeletonMambaConfig(skeleton="ntu25", in_channels=3, dim=16, depth=1, heads=2, mlp_dim=32, mixer=MIXER)


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _sm(*args: str, cwd: Path) -> list[str]:
    """``sm ARGS`` under the memory limit: its stderr lines, after checking exit 2 and one line."""
    proc = subprocess.run(
        [sm_executable(), *args],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=_limit_memory,
        cwd=cwd,
    )
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    return lines


@pytest.fixture
def folder(tmp_path) -> Path:
    """A tiny backbone's pretrained folder."""
    torch.manual_seed(0)
    SkeletonMamba(TINY).save_pretrained(tmp_path / "net")
    return tmp_path / "net"


def _edit_config(folder: Path, **init) -> None:
    config = json.loads((folder / CONFIG_NAME).read_text())
    config["init"]["config"].update(init)
    (folder / CONFIG_NAME).write_text(json.dumps(config))


# ------------------------------------------------------------------------------ sizes before allocation


@pytest.mark.parametrize(
    "field, value, expected",
    [
        ("dim", 1_000_000, "config.dim = 1000000: a size is an integer from 0 to 4,096"),
        ("depth", 10**9, "config.depth = 1000000000: a size is an integer from 0 to 256"),
        ("mlp_dim", -5, "config.mlp_dim = -5: a size is an integer from 0 to 65,536"),
        (
            "mixer",
            {**json.loads(json.dumps({"d_state": 10**7})), "_type": "MixerConfig"},
            "d_state = 10000000",
        ),
    ],
)
def test_sizes_beyond_their_bounds_are_refused_before_building(folder, monkeypatch, field, value, expected):
    _edit_config(folder, **{field: value})
    monkeypatch.setattr(SkeletonMamba, "__init__", lambda *a, **k: pytest.fail("built before the check"))
    with pytest.raises(PretrainedError, match=expected) as info:
        SkeletonMamba.from_pretrained(folder)
    assert str(folder / CONFIG_NAME) in str(info.value)


def test_sizes_within_bounds_but_too_many_values_are_refused_from_the_meta_build(folder):
    _edit_config(folder, dim=4096, depth=256, mlp_dim=65_536)  # each within its bound: ~10^11 values
    start = time.monotonic()
    with pytest.raises(PretrainedError, match=rf"values, more than a network's {MAX_PARAMETERS:,}"):
        SkeletonMamba.from_pretrained(folder)
    assert time.monotonic() - start < 120  # built on meta: no memory, bounded time


def test_every_network_builds_on_meta_with_the_shapes_and_types_of_the_real_one():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, network, _ in _networks():
            expected = meta_state(type(network), network.pretrained_init_args())
            real = network.state_dict()
            assert list(expected) == list(real), name
            for key, tensor in expected.items():
                assert tensor.device.type == "meta" and tensor.shape == real[key].shape, (name, key)
                assert tensor.dtype == real[key].dtype, (name, key)


def test_sm_export_onnx_refuses_a_huge_folder_under_a_memory_limit(folder, tmp_path):
    _edit_config(folder, dim=4096, depth=200, mlp_dim=60_000)
    (line,) = _sm("export-onnx", "--pretrained", str(folder), "--out", str(tmp_path / "onnx"), cwd=tmp_path)
    assert str(folder / CONFIG_NAME) in line and "values, more than a network's" in line
    assert not (tmp_path / "onnx").exists()


# ------------------------------------------------------------------------------ the safetensors header


def _write_header(path: Path, header: dict, data: bytes = b"") -> None:
    text = json.dumps(header).encode()
    path.write_bytes(struct.pack("<Q", len(text)) + text + data)


def test_header_that_does_not_fit_the_config_is_refused_before_reading_tensors(folder, monkeypatch):
    _edit_config(folder, dim=32, mlp_dim=64)  # the weights are of dim 16
    import safetensors.torch

    monkeypatch.setattr(safetensors.torch, "load_file", lambda *a, **k: pytest.fail("tensors read"))
    with pytest.raises(
        PretrainedError, match=r"model.safetensors: tensor '.*' has shape \(.*16.*\), SkeletonMamba"
    ):
        SkeletonMamba.from_pretrained(folder)


def test_a_million_empty_tensors_are_refused_at_once(tmp_path):
    entry = {"dtype": "F32", "shape": [0], "data_offsets": [0, 0]}
    _write_header(tmp_path / "million.safetensors", {f"t{i}": entry for i in range(1_000_000)})
    _write_header(tmp_path / "many.safetensors", {f"t{i}": entry for i in range(MAX_TENSORS + 1)})
    start = time.monotonic()
    with pytest.raises(PretrainedError, match="a safetensors header of .* bytes, more than 16,777,216"):
        read_safetensors_header(tmp_path / "million.safetensors", PretrainedError)
    with pytest.raises(
        PretrainedError, match=f"declares {MAX_TENSORS + 1:,} tensors, more than {MAX_TENSORS:,}"
    ):
        read_safetensors_header(tmp_path / "many.safetensors", PretrainedError)
    assert time.monotonic() - start < 30


@pytest.mark.parametrize(
    "header, data, expected",
    [
        ({"w": {"dtype": "F32", "shape": [4], "data_offsets": [0, 16]}}, b"\0" * 8, "truncated or padded"),
        ({"w": {"dtype": "F32", "shape": [4], "data_offsets": [0, 8]}}, b"\0" * 8, "needs 16 bytes"),
        ({"w": {"dtype": "C64", "shape": [1], "data_offsets": [0, 8]}}, b"\0" * 8, "dtype 'C64' is not one"),
        ({"w": {"dtype": "F32", "shape": [-1], "data_offsets": [0, 4]}}, b"\0" * 4, "is not a list of at"),
        ({"a": {"dtype": "F32", "shape": [1], "data_offsets": [0, 4]},
          "b": {"dtype": "F32", "shape": [1], "data_offsets": [0, 4]}}, b"\0" * 8, "overlaps another"),
    ],
)  # fmt: skip
def test_a_header_that_lies_about_the_data_is_refused(tmp_path, header, data, expected):
    _write_header(tmp_path / "w.safetensors", header, data)
    with pytest.raises(PretrainedError, match=expected):
        read_safetensors_header(tmp_path / "w.safetensors", PretrainedError)


def test_a_truncated_weights_file_is_refused_naming_it(folder):
    data = (folder / WEIGHTS_NAME).read_bytes()
    (folder / WEIGHTS_NAME).write_bytes(data[: len(data) - 100])
    with pytest.raises(PretrainedError, match=r"model.safetensors: truncated or padded"):
        SkeletonMamba.from_pretrained(folder)
    (folder / WEIGHTS_NAME).write_bytes(data[:5])
    with pytest.raises(PretrainedError, match="less than its header length"):
        SkeletonMamba.from_pretrained(folder)


# ------------------------------------------------------------------------------ the tensors


@pytest.mark.parametrize(
    "poison, expected",
    [
        (lambda t: t.fill_(math.nan), "weights are not finite"),
        (lambda t: t.fill_(math.inf), "weights are not finite"),
        (lambda t: t.to(torch.int64), "is stored as torch.int64, SkeletonMamba holds torch.float32"),
        (lambda t: t > 0, "is stored as torch.bool, SkeletonMamba holds torch.float32"),
    ],
    ids=["nan", "inf", "int", "bool"],
)
def test_poisoned_weights_are_refused(folder, poison, expected):
    from safetensors.torch import load_file

    tensors = load_file(folder / WEIGHTS_NAME)
    key = next(k for k, t in tensors.items() if t.is_floating_point() and t.numel() > 1)
    tensors[key] = poison(tensors[key].clone())
    save_file(tensors, folder / WEIGHTS_NAME)
    with pytest.raises(PretrainedError, match=expected) as info:
        SkeletonMamba.from_pretrained(folder)
    assert str(folder / WEIGHTS_NAME) in str(info.value) and key in str(info.value)


# ------------------------------------------------------------------------------ class paths and commands


def _stream_folder(tmp_path: Path) -> Path:
    from skeleton_mamba.tasks.stream.module import StreamDanceModule

    torch.manual_seed(0)
    module = StreamDanceModule(
        backbone=SkeletonMambaConfig(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MIXER)
    )
    hparams = {**dict(module.hparams), "_class_path": "skeleton_mamba.tasks.stream.module.StreamDanceModule"}
    ckpt = tmp_path / "stream.ckpt"
    torch.save({"state_dict": module.state_dict(), "hyper_parameters": hparams,
                "pytorch-lightning_version": lightning.__version__}, ckpt)  # fmt: skip
    assert sm(["export-pretrained", "--ckpt", str(ckpt), "--out", str(tmp_path / "dancer")]) == 0
    return tmp_path / "dancer"


@pytest.mark.parametrize(
    "where, value, expected",
    [
        ("class", "os.system", "names 'os.system', outside the project's modules"),
        ("module.class_path", "subprocess.Popen", "holds a subprocess.Popen, not a StreamDanceModule"),
        ("module.hparams.optimizer", {"class_path": "builtins.exec"}, "names 'builtins.exec', outside"),
        (
            "module.class_path",
            "skeleton_mamba.pretrained.mixin.PretrainedMixin",
            "holds a skeleton_mamba.pretrained.mixin",
        ),
        ("module.hparams.backbone.dim", 10**8, "dim = 100000000: a size is an integer"),
    ],
)
def test_sm_stream_refuses_a_hostile_folder_on_one_line(tmp_path, where, value, expected):
    folder = _stream_folder(tmp_path)
    config = json.loads((folder / CONFIG_NAME).read_text())
    *parents, last = where.split(".")
    target = config
    for key in parents:
        target = target[key]
    target[last] = value
    (folder / CONFIG_NAME).write_text(json.dumps(config))
    song = write_music(tmp_path / "song.wav", synthesize_music(120.0, 1.0, sr=22050, seed=3))
    (line,) = _sm("stream", "--ckpt", str(folder), "--music", str(song), "--out", "live", cwd=tmp_path)
    assert str(folder / CONFIG_NAME) in line and expected in line, line


def test_an_expanded_tensor_of_a_trillion_elements_is_refused(tmp_path):
    path = tmp_path / "expanded.ckpt"
    torch.save({"state_dict": {"w": torch.zeros(1).expand(10**12)}, "hyper_parameters": {}}, path)
    assert path.stat().st_size < 10_000
    with pytest.raises(
        CheckpointError, match=r"\['state_dict'\]\['w'\] is a tensor of 1,000,000,000,000 elements"
    ):
        load_checkpoint(path)
    (line,) = _sm("export-pretrained", "--ckpt", str(path), "--out", "x", cwd=tmp_path)
    assert str(path) in line and "an expanded view" in line


def test_a_truncated_checkpoint_names_the_file(tmp_path):
    path = tmp_path / "cut.ckpt"
    torch.save({"state_dict": {"w": torch.randn(1000, 100)}, "hyper_parameters": {}}, path)
    data = path.read_bytes()
    messages = set()
    for cut in range(0, len(data), len(data) // 50):
        path.write_bytes(data[:cut])
        with pytest.raises(CheckpointError) as info:
            load_checkpoint(path)
        assert str(path) in str(info.value) and "\n" not in str(info.value)
        messages.add(str(info.value))
    assert any("truncated or damaged: Invalid argument" in m for m in messages), messages


def test_sm_validate_names_the_folder_not_its_temporary_checkpoint(tmp_path, monkeypatch, capsys):
    """``sm validate --ckpt_path FOLDER`` whose hyper-parameters the recipe's parser refuses: the line names
    FOLDER, not the checkpoint written from it in a temporary folder."""
    folder = _stream_folder(tmp_path)
    config = json.loads((folder / CONFIG_NAME).read_text())
    config["module"]["hparams"]["lr"] = "fast"
    (folder / CONFIG_NAME).write_text(json.dumps(config))
    monkeypatch.chdir(tmp_path)
    recipe = [
        "--recipe", "stream_dance_demo.yaml", "--trainer.logger=false", "--trainer.enable_progress_bar=false",
        f"--trainer.default_root_dir={tmp_path}", f"--data.init_args.root={tmp_path / 'data'}",
    ]  # fmt: skip
    capsys.readouterr()
    assert sm(["validate", *recipe, "--ckpt_path", str(folder)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"sm validate: error: {folder} (hyper-parameters)") and "lr" in err, err
    assert "sm-pretrained-" not in err and len(err.splitlines()) == 1


def test_exported_files_have_the_umasks_mode(tmp_path):
    previous = os.umask(0o022)
    try:
        folder = _stream_folder(tmp_path)
    finally:
        os.umask(previous)
    modes = {p.name: p.stat().st_mode & 0o777 for p in folder.iterdir()}
    assert set(modes.values()) == {0o644}, modes
