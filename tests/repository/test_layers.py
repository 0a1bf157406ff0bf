"""The layers of docs/architecture.md, enforced: import-linter's contracts (``[tool.importlinter]`` in
pyproject.toml) on the package as it is installed, and the checks the contracts cannot state.

``tasks/`` is installed as ``skeleton_mamba.tasks`` and ``recipes/`` as ``skeleton_mamba.recipes``
(setup.py's ``package_dir``); import-linter reads packages from folders, so the test lays the three folders
out as a wheel does (``skeleton_mamba/tasks``, ``skeleton_mamba/recipes``) in a temporary folder and lints
that.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib", reason="tomllib is in the standard library from Python 3.11")

REPO = Path(__file__).resolve().parents[2]
# the tasks, as pyproject.toml registers them (entry points of skeleton_mamba.tasks)
TASKS = tuple(
    tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["entry-points"]["skeleton_mamba.tasks"]
)


@pytest.fixture(scope="module")
def installed_layout(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("layout")
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(REPO / "skeleton_mamba", root / "skeleton_mamba", ignore=ignore)
    shutil.copytree(REPO / "tasks", root / "skeleton_mamba" / "tasks", ignore=ignore)
    shutil.copytree(REPO / "recipes", root / "skeleton_mamba" / "recipes", ignore=ignore)
    shutil.copy(REPO / "pyproject.toml", root / "pyproject.toml")
    return root


def _lint(root: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(root)}
    lint = Path(sys.executable).with_name("lint-imports")
    command = [str(lint)] if lint.exists() else [sys.executable, "-m", "importlinter.cli"]
    return subprocess.run(
        [*command, "--config", "pyproject.toml", "--no-cache"],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_import_linter_contracts_are_kept(installed_layout):
    proc = _lint(installed_layout)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert "Contracts: 2 kept, 0 broken." in proc.stdout


def test_the_contracts_fail_on_a_wrong_way_import(installed_layout, tmp_path):
    """A toolkit module importing a task, and one task importing another, each break a contract."""
    broken = tmp_path / "broken"
    shutil.copytree(installed_layout, broken)
    toolkit = broken / "skeleton_mamba" / "tasks" / "motion" / "formats" / "bvh.py"
    toolkit.write_text(toolkit.read_text() + "\nimport skeleton_mamba.tasks.qean.model  # noqa\n")
    task = broken / "skeleton_mamba" / "tasks" / "stream" / "model.py"
    task.write_text(task.read_text() + "\nimport skeleton_mamba.tasks.egodance.model  # noqa\n")
    backbone = broken / "skeleton_mamba" / "mixer.py"
    backbone.write_text(backbone.read_text() + "\nimport numpy  # noqa\n")
    proc = _lint(broken)
    assert proc.returncode != 0
    assert "Contracts: 0 kept, 2 broken." in proc.stdout, proc.stdout[-4000:]
    for edge in (
        "skeleton_mamba.tasks.motion.formats.bvh -> skeleton_mamba.tasks.qean.model",
        "skeleton_mamba.tasks.stream.model -> skeleton_mamba.tasks.egodance.model",
        "skeleton_mamba.mixer -> numpy",
    ):
        assert edge in proc.stdout, edge


def test_the_backbone_contract_names_every_backbone_module():
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"]
    (backbone,) = [c for c in config["contracts"] if c["type"] == "forbidden"]
    named = set(backbone["source_modules"])
    on_disk = {
        f"skeleton_mamba.{p.stem if p.is_file() else p.name}"
        for p in (REPO / "skeleton_mamba").iterdir()
        if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").is_file()
    }
    assert named == on_disk
    (layers,) = [c for c in config["contracts"] if c["type"] == "layers"]
    top = {name.strip() for name in layers["layers"][0].split("|")}
    assert top == {f"skeleton_mamba.tasks.{task}" for task in TASKS}
    on_disk_tasks = {p.name for p in (REPO / "tasks").iterdir() if (p / "__init__.py").is_file()}
    assert on_disk_tasks == {*TASKS, "motion", "training"}


def _function_level_imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import inside a function of ``path`` that has no comment saying why."""
    lines = path.read_text().splitlines()
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        for inner in ast.walk(node):
            if isinstance(inner, ast.Import | ast.ImportFrom):
                if "# lazy:" not in lines[inner.lineno - 1]:
                    module = inner.module if isinstance(inner, ast.ImportFrom) else inner.names[0].name
                    found.append((inner.lineno, str(module)))
    return found


def test_imports_sit_at_module_top_or_say_why_they_are_lazy():
    """An import inside a function carries a ``# lazy: <reason>`` comment (start-up time, optional dep)."""
    offenders = [
        f"{path.relative_to(REPO)}:{line} {module}"
        for folder in ("skeleton_mamba", "tasks")
        for path in sorted((REPO / folder).rglob("*.py"))
        for line, module in _function_level_imports(path)
    ]
    assert not offenders, "\n".join(offenders)
