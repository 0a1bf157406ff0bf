"""Packaging: the namespaced layout in wheels and editable installs, the light import, ``sm``."""

import json
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.helpers.wheel_build import HEAVY, build_wheel

REPO = Path(__file__).resolve().parents[2]


def _python(code: str, **kwargs) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, **kwargs)
    return out.stdout


def test_import_skeleton_mamba_loads_only_torch_and_einops():
    code = (
        "import sys, json; import skeleton_mamba; "
        "m = skeleton_mamba.SkeletonMamba(skeleton_mamba.SkeletonMambaConfig(dim=64, depth=1, mlp_dim=8)); "
        f"print(json.dumps([n for n in {HEAVY!r} if n in sys.modules]))"
    )
    assert json.loads(_python(code)) == []


def test_sm_entry_point_help_and_version():
    from skeleton_mamba import __version__

    out = subprocess.run(["sm", "--version"], capture_output=True, text=True, check=True).stdout
    assert __version__ in out
    help_text = subprocess.run(
        [sys.executable, "-m", "skeleton_mamba.tasks", "--help"], capture_output=True, text=True, check=True
    ).stdout
    assert "usage: sm COMMAND" in help_text
    bad = subprocess.run(["sm", "no-such-command"], capture_output=True, text=True)
    assert bad.returncode == 2 and "unknown command" in bad.stderr


def test_current_install_resolves_mapped_packages():
    """Works for the install CI makes (editable): tasks/ and recipes/ live under our namespace."""
    code = (
        "import json, importlib.resources as r, skeleton_mamba.tasks as t, skeleton_mamba.recipes as rec; "
        "names = sorted(p.name for p in r.files('skeleton_mamba.recipes').iterdir()); "
        "print(json.dumps([t.__file__, rec.__file__, [n for n in names if n.endswith('.yaml')]]))"
    )
    tasks_file, recipes_file, yamls = json.loads(_python(code, cwd="/"))
    assert Path(tasks_file).parent.name == "tasks" and Path(recipes_file).parent.name == "recipes"
    assert yamls == sorted(p.name for p in (REPO / "recipes").glob("*.yaml"))
    assert len(yamls) > 0
    with pytest.raises(subprocess.CalledProcessError):
        _python("import tasks", cwd="/")  # no generic top-level name is installed


def test_wheel_installs_tasks_and_recipes_inside_the_namespace(tmp_path):
    wheel, _ = build_wheel(REPO, tmp_path / "wheel")
    names = zipfile.ZipFile(wheel).namelist()
    assert "skeleton_mamba/tasks/__init__.py" in names
    assert "skeleton_mamba/recipes/__init__.py" in names
    assert not any(n.startswith(("tasks/", "recipes/", "tests/", "benchmarks/")) for n in names)
    recipe_files = sorted(p.name for p in (REPO / "recipes").rglob("*.yaml"))
    assert (
        sorted(Path(n).name for n in names if n.startswith("skeleton_mamba/recipes/") and n.endswith(".yaml"))
        == recipe_files
    )
    data_files = sorted(str(p.relative_to(REPO / "tasks")) for p in (REPO / "tasks").rglob("*.txt"))
    for rel in data_files:
        assert f"skeleton_mamba/tasks/{rel}" in names
    # A regular (non-editable) install of that wheel imports from its own location.
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        check=True,
        capture_output=True,
    )
    code = (
        f"import sys; sys.path.insert(0, {str(target)!r}); import importlib.resources as r; "
        "import skeleton_mamba.tasks as t; print(t.__file__); "
        "print(len([p for p in r.files('skeleton_mamba.recipes').iterdir() if p.name.endswith('.yaml')]))"
    )
    tasks_file, n_yaml = _python(code, cwd=str(tmp_path)).split()
    assert tasks_file.startswith(str(target))
    assert int(n_yaml) == len(list((REPO / "recipes").glob("*.yaml")))
