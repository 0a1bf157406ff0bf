"""The task registry (``tasks/training/registry.py``): every task declares itself once in its own folder
(``task.py``), is found through the ``skeleton_mamba.tasks`` entry points, and the machinery names no task.

A task in another distribution is found the same way: ``tests/test_external_task.py``.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import subprocess
import sys
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

from skeleton_mamba.tasks.training import cli, registry
from skeleton_mamba.tasks.training.contract_links import contract_class_of, contract_links
from skeleton_mamba.tasks.training.lightning_cli import import_task_modules, registered_links
from skeleton_mamba.tasks.training.registry import Command, RegistryError, TaskSpec, registered_tasks

tomllib = pytest.importorskip("tomllib", reason="tomllib is in the standard library from Python 3.11")

REPO = Path(__file__).resolve().parents[1]
ENTRY_POINTS = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["entry-points"]
TASKS = tuple(
    ENTRY_POINTS[registry.ENTRY_POINT_GROUP]
)  # this repository's tasks, as pyproject registers them
# the tasks whose declarations are pinned below
KNOWN = ("egodance", "qean", "recognition", "stream", "text2motion")


def _load(target: str):
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def test_the_repository_tasks_register_themselves_through_their_entry_points():
    specs = {spec.name: spec for spec in registered_tasks()}
    assert set(specs) >= set(TASKS) >= set(KNOWN)  # (and any task another installed distribution adds)
    assert ENTRY_POINTS[registry.ENTRY_POINT_GROUP] == {
        t: f"skeleton_mamba.tasks.{t}.task:TASK" for t in TASKS
    }
    on_disk = {p.parent.name for p in (REPO / "tasks").glob("*/task.py")}
    assert on_disk == set(TASKS)  # a task folder without its entry point is never found
    for name, spec in ((t, specs[t]) for t in TASKS):
        assert spec.package == f"skeleton_mamba.tasks.{name}"
        assert spec.modules == (f"{spec.package}.module", f"{spec.package}.data")
        for command in [*spec.commands.values(), *(c for v in spec.variants.values() for c in v.values())]:
            assert callable(_load(command.parser))  # torch-free parser modules
            module, function = command.run.split(":")
            assert importlib.util.find_spec(module) is not None, command.run
        for network, target in spec.networks.items():
            assert callable(_load(target)), (network, target)
    assert {s.title for s in specs.values()} == {
        "EgoDance",
        "QEAN",
        "recognition",
        "streaming",
        "text-to-motion",
    }
    imported = import_task_modules()
    assert [m for m in imported if m.startswith("skeleton_mamba.")] == [
        m for t in sorted(TASKS) for m in specs[t].modules
    ]


def test_sm_takes_its_task_commands_and_variants_from_the_registrations():
    by_task = {spec.name: set(spec.commands) for spec in registered_tasks()}
    assert {t: by_task[t] for t in KNOWN} == {
        "egodance": {"make-ego", "dance"},
        "qean": set(),
        "recognition": {"prepare"},
        "stream": {"stream", "export-web"},
        "text2motion": {"generate", "convert"},
    }
    assert set(cli.COMMANDS) == set(cli.MACHINERY_COMMANDS).union(*by_task.values())
    assert cli.TASK_VARIANTS["stream"]["recognition"].run == "skeleton_mamba.tasks.recognition.online:main"


PAIRS = [  # (data module, module) of the recipes
    ("recognition.data.RecognitionDataModule", "recognition.module.ActionRecognitionModule"),
    ("recognition.data.SyntheticRecognitionDataModule", "recognition.module.ActionRecognitionModule"),
    ("egodance.data.EgoDanceDataModule", "egodance.module.EgoDanceModule"),
    ("egodance.data.SyntheticEgoDanceDataModule", "egodance.module.EgoDanceModule"),
    ("qean.data.AISTPPDanceDataModule", "qean.module.QEANModule"),
    ("stream.data.StreamDanceDataModule", "stream.module.StreamDanceModule"),
    ("text2motion.data.HumanML3DDataModule", "text2motion.module.TextToMotionModule"),
    ("text2motion.data.SyntheticTextMotionDataModule", "text2motion.module.TextToMotionModule"),
    ("text2motion.evaluator_data.T2MEvaluatorDataModule", "text2motion.evaluator_module.T2MEvaluatorModule"),
]


def _class(path: str) -> type:
    module, _, name = f"skeleton_mamba.tasks.{path}".rpartition(".")
    return getattr(importlib.import_module(module), name)


def test_the_links_derived_from_the_contracts_are_those_the_machinery_listed_before():
    """The data-to-model links, now read off each data module's contract and its model's arguments, are the
    14 of the former single list (all but ``batch_size`` on the modules without that argument)."""
    links = {
        link
        for data, module in PAIRS
        for link in contract_links(contract_class_of(_class(data)), _class(module))
    }
    assert links == {
        ("num_classes", "num_classes"), ("skeleton", "skeleton"), ("in_channels", "in_channels"),
        ("batch_size", "batch_size"), ("image_size", "image_size"), ("fps", "fps"),
        ("music_dim", "network.music_dim"), ("music_dim", "music_dim"),
        ("seed_frames", "network.seed_frames"), ("music_frames", "network.music_frames"),
        ("predict_frames", "network.predict_frames"), ("generate_frames", "generate_frames"),
        ("window", "window"), ("canonicalize_init_head", "canonicalize_init_head"),
    }  # fmt: skip
    assert set(registered_links()) == links  # what sm fit links: every registered pair's, each once
    qean = contract_links(contract_class_of(_class(PAIRS[4][0])), _class(PAIRS[4][1]))
    assert ("seed_frames", "network.seed_frames") in qean and (
        "music_cache_dir",
        "music_cache_dir",
    ) not in qean


def test_reading_the_registry_imports_no_torch():
    code = (
        "import sys; from skeleton_mamba.tasks.training.registry import registered_tasks; "
        "n = len(registered_tasks()); print(n, [m for m in ('torch', 'lightning') if m in sys.modules])"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.stdout.split(None, 1) == [str(len(TASKS)), "[]\n"], done.stderr


def _strings_and_imports(path: Path) -> list[tuple[int, str]]:
    """(line, text) of every import and every string constant but docstrings in ``path``."""
    tree = ast.parse(path.read_text())
    docstrings = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.append((node.lineno, node.module))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            found.append((node.lineno, node.value))
    return found


def test_the_machinery_names_no_task():
    """No import, and no string but docstrings, in ``tasks/training/`` names a task's package, title or
    network: what the machinery knows of a task comes from its registration."""
    specs = registered_tasks()
    packages = [spec.package for spec in specs]
    words = {spec.title for spec in specs} | {n for spec in specs for n in spec.networks}
    offenders = []
    for path in sorted((REPO / "tasks" / "training").rglob("*.py")):
        for line, text in _strings_and_imports(path):
            if any(p in text for p in packages) or text in words:
                offenders.append(f"{path.relative_to(REPO)}:{line} {text!r}")
    assert not offenders, "\n".join(offenders)


def _points(*items: tuple[str, str]) -> list[EntryPoint]:
    return [EntryPoint(name, value, registry.ENTRY_POINT_GROUP) for name, value in items]


HERE = __name__  # the entry points below name objects of this module
SPEC = TaskSpec("demo", "demo", "demo_pkg", commands={"go": Command("demo_pkg.cli:main", "go")})


@pytest.mark.parametrize(
    ("points", "message"),
    [
        (
            _points(("demo", f"{HERE}:SPEC"), ("other", f"{HERE}:OTHER_GO")),
            "command 'go' is task",
        ),
        (_points(("demo", f"{HERE}:TASKS")), "names a tuple, not a TaskSpec"),
        (_points(("renamed", f"{HERE}:SPEC")), "its TaskSpec is named 'demo'"),
        (_points(("demo", "no_such_module_here:TASK")), "does not load"),
    ],
)
def test_a_broken_registration_is_refused_naming_its_entry_point(monkeypatch, points, message):
    monkeypatch.setattr(
        registry, "entry_points", lambda group: points if group == registry.ENTRY_POINT_GROUP else []
    )
    with pytest.raises(RegistryError, match=message) as caught:
        registry.registered_tasks.__wrapped__()
    assert "\n" not in str(caught.value) and registry.ENTRY_POINT_GROUP in str(caught.value)


OTHER_GO = TaskSpec("other", "other", "other_pkg", commands={"go": Command("other_pkg.cli:main", "go")})
