"""Output folders: no file of the user's is replaced without being asked.

Every command that writes into a folder (``--out DIR``: ``sm export-pretrained``, ``sm export-onnx``,
``sm dance``, ``sm stream``, ``sm generate``, ``sm make-ego``) claims it first with
:func:`claim_output_folder`, before any work:

- a missing folder is created, an empty one taken;
- a folder holding only the command's own earlier output is taken again: it is recognised by the
  command's marker (``config.json`` of a pretrained folder, ``export.json`` of the ONNX graphs,
  ``build.json`` of an EgoAIST++ build) and its exact file set, or, for the other commands, by the
  manifest :data:`MANIFEST` the command wrote there (:func:`record_outputs`, before its first file),
  which lists every file it wrote;
- any other non-empty folder (``--out .`` in a project, a folder of the user's files) is refused with one
  line naming it and a file it holds, unless ``--overwrite`` is given; even then only the command's own
  file names are written, nothing is deleted.

A command told to write one named file and files beside it (``sm dance --out FILE.npz`` also writes
``FILE.bvh``, ``FILE.glb``, ...) checks those others with :func:`claim_output_files`: an existing one is
refused unless ``--overwrite`` is given (the named file itself was asked for). The files themselves are
written atomically (:mod:`.atomic`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable
from pathlib import Path

from skeleton_mamba.bounded_read import read_json
from skeleton_mamba.tasks.motion.atomic import atomic_open
from skeleton_mamba.tasks.motion.errors import InputError

__all__ = ["MANIFEST", "OVERWRITE_HELP", "claim_output_files", "claim_output_folder", "record_outputs"]

MANIFEST = ".sm-output.json"
OVERWRITE_HELP = (
    "write into --out even when it holds files this command did not write (its own file names are "
    "replaced, nothing is deleted)"
)


def _manifest_files(folder: Path, command: str) -> set[str] | None:
    """The files ``command``'s manifest in ``folder`` lists, or None when there is no such manifest."""
    path = folder / MANIFEST
    if not path.is_file():
        return None
    try:
        record = read_json(path, max_bytes=1 << 20, what="output manifest", error=InputError)
    except InputError:
        return None
    files = record.get("files") if isinstance(record, dict) and record.get("command") == command else None
    return {f for f in files if isinstance(f, str)} if isinstance(files, list) else None


def claim_output_folder(
    folder: str | os.PathLike[str],
    command: str,
    files: Iterable[str],
    *,
    overwrite: bool = False,
    marker: Callable[[Path], bool] | None = None,
) -> Path:
    """Check, before any work, that ``command`` may write ``files`` (names inside ``folder``) into
    ``folder`` (module docstring); nothing is created yet (:func:`record_outputs` does, before the first
    file is written). Returns the folder.

    Args:
        folder: the ``--out`` folder.
        command: the command's name (``"sm dance"``), stored in the manifest and named in the refusal.
        files: the file names the command writes there (a superset is fine).
        overwrite: the user's ``--overwrite``.
        marker: for a command whose folder is recognised by its own files instead of a manifest (a
            pretrained folder that must hold nothing else): True when ``folder`` holds that command's
            earlier output. The folder may then hold ``files`` only.

    Raises:
        InputError: ``folder`` is not empty and not the command's earlier output, and ``overwrite`` is
            not given; or it is a file.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder}: is a file (a folder is expected)")
    entries = sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []
    if marker is not None:
        ours = set(files)
        own = not entries or (marker(folder) and set(entries) <= ours)
    else:
        listed = _manifest_files(folder, command)
        ours = (listed or set()) | {MANIFEST}
        own = not entries or (listed is not None and set(entries) <= ours)
    if not own and not overwrite:
        foreign = [e for e in entries if e not in ours] or entries
        raise InputError(
            f"{folder}: not empty and not an earlier output of {command} (it holds {len(entries)} entries, "
            f"e.g. {foreign[0]!r}); choose a new folder, or pass --overwrite to write into it anyway"
        )
    return folder


def record_outputs(folder: str | os.PathLike[str], command: str, files: Iterable[str]) -> Path:
    """Create ``folder`` and add ``files`` to ``command``'s manifest in it (after
    :func:`claim_output_folder`, before the first file is written); returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    recorded = sorted((_manifest_files(folder, command) or set()) | set(files))
    with atomic_open(folder / MANIFEST, "w", encoding="utf-8") as f:
        f.write(json.dumps({"command": command, "files": recorded}, indent=2) + "\n")
    return folder


def claim_output_files(
    paths: Iterable[str | os.PathLike[str]], asked: str | os.PathLike[str], *, overwrite: bool = False
) -> None:
    """Refuse to replace an existing file among ``paths`` other than ``asked`` (the file the user named),
    unless ``overwrite``.

    Raises:
        InputError: naming the first such file.
    """
    existing = [Path(p) for p in paths if Path(p) != Path(asked) and os.path.lexists(p)]
    if existing and not overwrite:
        raise InputError(
            f"{existing[0]}: exists and would be replaced (written beside {asked}); remove it, choose another"
            " name, or pass --overwrite"
        )
