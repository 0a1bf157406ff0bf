"""``pip install skeleton-mamba`` without extras is the backbone alone; ``sm`` names the extra to install.

The slow test builds the wheel, installs it without extras into a fresh virtual environment (no system
site-packages; torch first, as CI and the README install it) and checks the backbone there: the import, a
forward pass, a pretrained folder saved and loaded, no Lightning, and ``sm`` answering with the extra to
install and exit code 2. It needs a package index (PyPI or a local one); without one it skips, saying so.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import venv
from pathlib import Path

import pytest
import torch

from skeleton_mamba.tasks.training import cli
from tests.helpers.wheel_build import build_wheel

REPO = Path(__file__).resolve().parents[2]
SOURCES = ["pyproject.toml", "setup.py", "README.md", "LICENSE", "skeleton_mamba", "tasks", "recipes"]
TASKS_HINT = 'pip install "skeleton-mamba[tasks]"'
# Not one of them may come with the core install (the [tasks] and [export] extras' packages).
EXTRA_ONLY = ["lightning", "pytorch_lightning", "librosa", "transformers", "trimesh", "onnx", "onnxruntime"]

CORE_CHECK = """
import importlib.util, json, sys, tempfile
import torch
import skeleton_mamba
from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig

torch.manual_seed(0)
config = SkeletonMambaConfig(skeleton="ntu25", in_channels=3, dim=32, depth=1, mlp_dim=16)
model = SkeletonMamba(config).eval()
x = torch.randn(2, 12, 25, 3)
mask = torch.arange(12)[None] < torch.tensor([[12], [7]])
with torch.no_grad():
    y = model(x, mask=mask)
    with tempfile.TemporaryDirectory() as folder:
        model.save_pretrained(folder)
        loaded = SkeletonMamba.from_pretrained(folder).eval()
        y_loaded = loaded(x, mask=mask)
print(json.dumps({
    "file": skeleton_mamba.__file__,
    "shape": list(y.shape),
    "finite": bool(torch.isfinite(y).all()),
    "max_diff_loaded": float((y - y_loaded).abs().max()),
    "installed_extras": [n for n in EXTRA_ONLY if importlib.util.find_spec(n) is not None],
}))
"""


def test_every_module_sm_checks_is_installed_with_the_extras():
    """No typo in the names ``sm`` checks: the dev install (every extra) has each of them."""
    for extra, modules in [("tasks", cli.TASKS_EXTRA_MODULES), *cli.COMMAND_EXTRAS.values()]:
        assert cli.missing_extra(extra, modules) is None


def test_sm_without_the_tasks_extra_names_it_on_one_line(monkeypatch, capsys):
    monkeypatch.setattr(cli, "TASKS_EXTRA_MODULES", ("lightning", "no_such_module_sm_needs"))
    for argv in ([], ["--help"], ["fit", "--recipe", "egodance_demo.yaml"], ["render", "x.npz"]):
        assert cli.main(argv) == 2
        out, err = capsys.readouterr()
        assert out == ""
        assert err == f"sm: needs the [tasks] extra (not installed: no_such_module_sm_needs): {TASKS_HINT}\n"
    assert cli.main(["--version"]) == 0  # the version needs no extra
    assert "skeleton-mamba" in capsys.readouterr().out


def test_export_onnx_without_the_export_extra_names_it(monkeypatch, capsys):
    monkeypatch.setitem(cli.COMMAND_EXTRAS, "export-onnx", ("export", ("onnx", "no_such_onnx_module")))
    assert cli.main(["export-onnx", "--help"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "sm export-onnx: error: needs the [export] extra (not installed: no_such_onnx_module): "
        'pip install "skeleton-mamba[export]"\n'
    )


def _run(cmd: list[str], **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, **kwargs)


def _last_line(result: subprocess.CompletedProcess) -> str:
    lines = (result.stderr or result.stdout).strip().splitlines()
    return lines[-1] if lines else f"exit {result.returncode}"


@pytest.mark.slow
def test_core_wheel_in_a_fresh_environment_is_the_backbone_alone(tmp_path):
    # A package index (PyPI, or a local index / wheel folder in pip's configuration) to install from.
    probe = _run(
        [sys.executable, "-m", "pip", "download", "--no-deps", "-q", "-d", str(tmp_path / "p"), "einops"]
    )
    if probe.returncode != 0:
        pytest.skip(f"no package index to install the core wheel's dependencies from: {_last_line(probe)}")

    # The wheel, built from a copy of the sources (the build leaves the repository untouched).
    source = tmp_path / "src"
    for name in SOURCES:
        path = REPO / name
        if path.is_dir():
            shutil.copytree(path, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            source.mkdir(exist_ok=True)
            shutil.copy2(path, source / name)
    wheel, output = build_wheel(source, tmp_path / "wheel")
    assert "SetuptoolsDeprecationWarning" not in output

    # A fresh environment, not seeing this one's packages: torch as CI installs it, then the wheel alone.
    env_dir = tmp_path / "env"
    venv.EnvBuilder(with_pip=True, system_site_packages=False, clear=True).create(env_dir)
    python, sm = str(env_dir / "bin" / "python"), str(env_dir / "bin" / "sm")
    torch_pin = f"torch=={torch.__version__.split('+')[0]}"
    for requirement in (torch_pin, str(wheel)):
        installed = _run([python, "-m", "pip", "install", "-q", requirement])
        if installed.returncode != 0 and requirement == torch_pin:
            pytest.skip(f"{torch_pin} cannot be installed from the package index: {_last_line(installed)}")
        assert installed.returncode == 0, installed.stdout + installed.stderr

    check = _run([python, "-c", f"EXTRA_ONLY = {EXTRA_ONLY!r}\n{CORE_CHECK}"], cwd=tmp_path)
    assert check.returncode == 0, check.stderr
    report = json.loads(check.stdout.strip().splitlines()[-1])
    assert report["file"].startswith(str(env_dir))  # the wheel's copy, not this checkout
    assert report["shape"] == [2, 12, 25, 32] and report["finite"]
    assert report["max_diff_loaded"] == 0.0
    assert report["installed_extras"] == []

    for argv in (["--help"], ["fit", "--recipe", "egodance_demo.yaml"]):
        result = _run([sm, *argv], cwd=tmp_path)
        assert result.returncode == 2, result.stdout + result.stderr
        assert result.stdout == ""
        lines = result.stderr.strip().splitlines()
        assert (
            len(lines) == 1 and lines[0].startswith("sm: needs the [tasks] extra") and TASKS_HINT in lines[0]
        )
        assert "lightning" in lines[0] and "Traceback" not in result.stderr
