"""Every ``>>>`` example of the packages, run by pytest's own doctest items (those ``--doctest-modules``
makes), with a shared namespace (kornia's way: ``doctest_namespace`` holds ``np`` and ``torch``).

The modules are found by walking the installed packages (the backbone and ``skeleton_mamba.tasks``), so no
list is kept by hand. They are imported by their installed names: ``tasks/`` is installed as
``skeleton_mamba.tasks`` by a package-dir mapping, and ``pytest --doctest-modules tasks/`` would import each
file again as ``tasks.<...>``, a second copy of every module (its registries and classes distinct from the
installed ones). The items sit under ``tests/repository/examples/<module>`` (``pytest tests/repository
-k "examples and not test_"`` runs them alone); the examples that write a file write it under
:func:`tempfile.mkdtemp`, pointed here at the test's temporary folder.
"""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
from pathlib import Path

import numpy as np
import pytest
import torch
from _pytest.doctest import DoctestItem, DoctestModule

import skeleton_mamba
import skeleton_mamba.tasks

EXAMPLES_ID = "tests/repository/examples"


def modules_with_examples() -> dict[str, Path]:
    """Every module of the installed packages whose source holds an example (``>>>``), with its file."""
    found = {}
    for package, prefix in (
        (skeleton_mamba, "skeleton_mamba."),
        (skeleton_mamba.tasks, "skeleton_mamba.tasks."),
    ):
        for info in pkgutil.walk_packages(package.__path__, prefix):
            spec = importlib.util.find_spec(info.name)
            if spec is not None and spec.origin and spec.origin.endswith(".py"):
                path = Path(spec.origin)
                if ">>>" in path.read_text(encoding="utf-8"):
                    found[info.name] = path
    return dict(sorted(found.items()))


class InstalledModuleDoctests(DoctestModule):
    """The doctest items of one installed module, imported by its dotted name (module docstring)."""

    module_name: str

    def _getobj(self):
        return importlib.import_module(self.module_name)


class PackageExamples(pytest.Collector):
    """One :class:`InstalledModuleDoctests` per module of :func:`modules_with_examples`."""

    def collect(self):
        for name, path in modules_with_examples().items():
            node = InstalledModuleDoctests.from_parent(self, path=path, nodeid=f"{EXAMPLES_ID}/{name}")
            node.module_name = name
            yield node


def pytest_collect_file(file_path: Path, parent: pytest.Collector):
    """Beside ``test_doctests.py`` (which checks what the examples cover), the examples themselves."""
    if file_path.name == "test_doctests.py" and file_path.parent == Path(__file__).parent:
        return PackageExamples.from_parent(parent, name="examples", nodeid=EXAMPLES_ID)
    return None


@pytest.fixture(autouse=True)
def _doctest_namespace_and_files(request, doctest_namespace, tmp_path, monkeypatch):
    """For the examples: ``np`` and ``torch`` in their namespace, and their files in the test's folder."""
    if isinstance(request.node, DoctestItem):
        doctest_namespace.update(np=np, torch=torch)
        monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
