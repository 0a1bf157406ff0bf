"""Journey (d): the demo's run folder and its generated data copied elsewhere (another disk, a colleague's
machine), then used from yet another working folder: ``sm dance --list-samples`` and ``--sample`` still find
the data, because a checkpoint stores its data root relative to itself and every sample's ``meta.json`` its
music and motion relative to the sample. Older checkpoints (root relative to where ``sm fit`` ran) and
older samples (absolute paths) are still read. A run folder copied without its data says how the demo
builds it (not "build AIST++")."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import lightning
import pytest
import torch

from skeleton_mamba.tasks.egodance.builder.layout import read_meta
from skeleton_mamba.tasks.egodance.data import SyntheticEgoDanceDataModule
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.training.checkpoints import RELATIVE_PATHS_KEY, CheckedCheckpointIO
from skeleton_mamba.tasks.training.cli import main as sm_main

RUN = Path("runs/egodance_demo/version_0/checkpoints/last.ckpt")


@pytest.fixture(scope="module")
def demo_folder(tmp_path_factory, tiny_egodance_module):
    """``work/`` where a tiny demo ran: ``runs/egodance_demo/data`` (9 generated dances, 16 px frames) and a
    checkpoint written by the trainer's checkpoint writer, with the data root as the recipe gives it."""
    work = tmp_path_factory.mktemp("work")
    cwd = os.getcwd()
    os.chdir(work)
    try:
        data = SyntheticEgoDanceDataModule(
            root="runs/egodance_demo/data", count=9, duration_s=5.0, frame_size=16, image_size=32, num_rooms=1
        )
        data.prepare_data()
        torch.manual_seed(0)
        module = tiny_egodance_module()
        checkpoint = {
            "state_dict": module.state_dict(),
            "hyper_parameters": dict(module.hparams),
            "datamodule_hyper_parameters": dict(data.hparams),
            "pytorch-lightning_version": lightning.__version__,
        }
        RUN.parent.mkdir(parents=True)
        CheckedCheckpointIO().save_checkpoint(checkpoint, RUN)
    finally:
        os.chdir(cwd)
    return work


def _listed(capsys) -> list[str]:
    return [line for line in capsys.readouterr().out.splitlines() if line and not line.startswith("#")]


def test_moved_run_and_data_still_list_and_dance(demo_folder, tmp_path, monkeypatch, capsys):
    stored = torch.load(demo_folder / RUN, weights_only=True)
    assert stored["datamodule_hyper_parameters"]["root"] == "../../data"  # from version_0/checkpoints/
    assert stored[RELATIVE_PATHS_KEY] == ["root"]
    sample = next((demo_folder / "runs/egodance_demo/data/ego/samples").iterdir())
    written = json.loads((sample / "meta.json").read_text())
    assert written["music"]["path_relative"] == f"../../../motions/{Path(written['music']['path']).name}"
    assert written["motion"]["source_relative"].startswith("../../../motions/")

    moved = tmp_path / "disk2" / "project"
    shutil.copytree(demo_folder / "runs", moved / "runs")
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")  # neither the old nor the new folder
    ckpt = moved / RUN
    assert sm_main(["dance", "--ckpt", str(ckpt), "--list-samples"]) == 0
    listed = _listed(capsys)
    assert len(listed) == 3  # 2 test + 1 val windows of the 9 dances
    assert all(Path(p).is_relative_to(moved / "runs/egodance_demo/data/ego/samples") for p in listed)
    meta = read_meta(listed[0])
    assert Path(meta["music"]["path"]).is_file() and Path(meta["motion"]["source"]).is_file()
    assert Path(meta["music"]["path"]).is_relative_to(moved)

    shutil.rmtree(demo_folder / "runs")  # the original is gone: only the copy is left
    try:
        args = ["dance", "--ckpt", str(ckpt), "--sample", listed[0], "--out", "out", "--steps", "1"]
        assert sm_main([*args, "--head", "oracle"]) == 0  # rendered: the music found from the moved sample
        assert load_motion(Path("out") / "dance.npz").num_frames == 150
        assert (Path("out") / "dance.mp4").stat().st_size > 0
    finally:
        shutil.copytree(moved / "runs", demo_folder / "runs")


def test_older_checkpoints_and_samples_are_read_too(demo_folder, tmp_path, monkeypatch, capsys):
    old = torch.load(demo_folder / RUN, weights_only=True)
    old.pop(RELATIVE_PATHS_KEY)
    old["datamodule_hyper_parameters"]["root"] = "runs/egodance_demo/data"  # as sm fit's folder saw it
    moved = tmp_path / "project"
    shutil.copytree(demo_folder / "runs", moved / "runs")
    torch.save(old, moved / RUN)
    sample = next((moved / "runs/egodance_demo/data/ego/samples").iterdir())
    meta = json.loads((sample / "meta.json").read_text())
    meta["music"].pop("path_relative")  # an older build: the absolute path alone
    (sample / "meta.json").write_text(json.dumps(meta))
    monkeypatch.chdir(tmp_path)
    assert sm_main(["dance", "--ckpt", str(moved / RUN), "--list-samples"]) == 0
    assert len(_listed(capsys)) == 3
    assert read_meta(sample)["music"]["path"] == meta["music"]["path"]


def test_a_run_copied_without_its_data_says_how_the_demo_builds_it(demo_folder, tmp_path, capsys):
    run_only = tmp_path / "runs/egodance_demo/version_0"
    shutil.copytree(demo_folder / "runs/egodance_demo/version_0", run_only)
    assert sm_main(["dance", "--ckpt", str(run_only / "checkpoints/last.ckpt"), "--list-samples"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sm fit --recipe egodance_demo.yaml" in err[0]
    assert "make-ego" not in err[0] and "AIST++" not in err[0]
