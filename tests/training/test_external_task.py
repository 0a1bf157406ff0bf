"""A task in another distribution (``tests/example_task/``: the gesture task of docs/architecture.md) is
found through its one entry point and runs through ``sm fit``, ``sm export-onnx`` and ``sm export-pretrained``
like the repository's own tasks, with no edit to Skeleton Mamba.

The example is pip-installed (its own wheel, no dependencies, no build isolation) into a temporary folder
that only the ``sm`` processes of this test see (``PYTHONPATH``), so the environment and the other tests
never see the gesture task.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).resolve().parents[1] / "example_task"


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    site = tmp_path_factory.mktemp("example_site")
    build = tmp_path_factory.mktemp("example_build")
    source = build / "example_task"
    subprocess.run(
        ["cp", "-r", str(EXAMPLE), str(source)], check=True
    )  # builds leave files beside the source
    pip = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index"]
    done = subprocess.run([*pip, "--target", str(site), str(source)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    return site


def _sm(site: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    command = [sys.executable, "-m", "skeleton_mamba.tasks", *args]
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)


def test_an_installed_task_trains_and_exports_through_sm(installed, tmp_path):
    recipe = installed / "sm_gesture" / "gesture_demo.yaml"
    fit = _sm(installed, tmp_path, "fit", "--recipe", str(recipe), "--trainer.max_steps", "2", "--quiet")
    assert fit.returncode == 0, fit.stderr[-3000:]
    (ckpt,) = (tmp_path / "runs" / "gesture_demo" / "version_0" / "checkpoints").glob("*.ckpt")
    config = (tmp_path / "runs" / "gesture_demo" / "version_0" / "config.yaml").read_text()
    assert "class_path: sm_gesture.module.GestureModule" in config  # the recipe's short name, resolved

    onnx = _sm(installed, tmp_path, "export-onnx", "--ckpt", str(ckpt), "--out", "onnx", "--check")
    assert onnx.returncode == 0, onnx.stderr[-3000:]
    record = json.loads((tmp_path / "onnx" / "export.json").read_text())
    assert record["network"] == "GestureClassifier" and list(record["graphs"]) == ["sequence"]
    sequence = record["graphs"]["sequence"]
    assert sequence["outputs"] == ["logits"] and sequence["inputs"]["x"]["shape"][2:] == [18, 2]
    assert sequence["max_abs_diff_vs_eager"] < 1e-4

    pretrained = _sm(installed, tmp_path, "export-pretrained", "--ckpt", str(ckpt), "--out", "pretrained")
    assert pretrained.returncode == 0, pretrained.stderr[-3000:]
    folder = json.loads((tmp_path / "pretrained" / "config.json").read_text())
    assert folder["class"] == "sm_gesture.model.GestureClassifier"
    assert folder["module"]["class_path"] == "sm_gesture.module.GestureModule"
    hparams = folder["module"]["hparams"]  # linked from the data module (the task's links; the module's own
    assert (hparams["num_classes"], hparams["skeleton"]) == (3, "openpose18")  # default is 4 classes)
    assert folder["init"]["num_classes"] == 3
    assert "wrote pretrained/ (GestureClassifier of sm_gesture.module.GestureModule)" in pretrained.stdout


def test_without_its_entry_point_the_task_is_foreign(tmp_path):
    """The same recipe with the task's package on the path but not installed (no entry point): its class
    paths are refused as outside the project's modules, as any unregistered module's."""
    recipe = tmp_path / "gesture_demo.yaml"  # the module by its full class path (no short names here)
    text = (EXAMPLE / "sm_gesture" / "gesture_demo.yaml").read_text()
    recipe.write_text(
        text.replace("class_path: GestureModule", "class_path: sm_gesture.module.GestureModule")
    )
    fit = _sm(EXAMPLE, tmp_path, "fit", "--recipe", str(recipe), "--trainer.max_steps", "2", "--quiet")
    assert fit.returncode == 2
    assert "outside the project's modules" in fit.stderr and "--allow-import sm_gesture" in fit.stderr
