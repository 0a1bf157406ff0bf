"""MkDocs hook: the installed package layout, for the API reference.

``tasks/`` is installed as ``skeleton_mamba.tasks`` (``setup.py``'s ``package_dir``), a mapping that the
static source reader of mkdocstrings (griffe) does not follow. Before the build this hook copies the Python
sources into ``build/api/skeleton_mamba/`` as they are installed (``skeleton_mamba/`` with ``tasks/`` inside
it), and ``mkdocs.yml`` points the Python handler there. Nothing is imported; new modules appear without an
edit.
"""

from __future__ import annotations

import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LAYOUT = ROOT / "build" / "api"
SOURCES = {"skeleton_mamba": ROOT / "skeleton_mamba", "skeleton_mamba/tasks": ROOT / "tasks"}


def _python_only(folder: str, names: list[str]) -> set[str]:
    """shutil.copytree's ignore: keep packages and ``.py`` files, nothing else."""
    return {n for n in names if not (n.endswith(".py") or (Path(folder) / n).is_dir()) or n == "__pycache__"}


def on_startup(**_kwargs) -> None:
    """Write ``build/api/skeleton_mamba`` before the handler reads its ``paths`` (they must exist then)."""
    on_pre_build()


def on_pre_build(**_kwargs) -> None:
    """Rebuild ``build/api/skeleton_mamba`` from the sources before every build (``mkdocs serve`` too)."""
    if LAYOUT.exists():
        shutil.rmtree(LAYOUT)
    for target, source in SOURCES.items():
        shutil.copytree(source, LAYOUT / target, ignore=_python_only, dirs_exist_ok=True)
