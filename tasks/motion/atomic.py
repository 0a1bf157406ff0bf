"""Atomic file writes for the toolkit: :mod:`skeleton_mamba.atomic` (the backbone's ``save_pretrained`` writes
through it too, so every writer of the project shares one implementation and one file mode), and the
commands' rule for an output file (:func:`output_file`)."""

from __future__ import annotations

from os import PathLike
from pathlib import Path

from skeleton_mamba.atomic import atomic_open, atomic_path, check_writable

__all__ = ["atomic_open", "atomic_path", "check_writable", "output_file"]


def output_file(path: str | PathLike[str], option: str = "--out") -> Path:
    """A user's output *file* (``sm render --out clip.mp4``): its folder must exist.

    The commands' policy: an output file goes into an existing folder (a typo such as ``/nonexistnt/x.mp4``
    must not create folders at the root); a command whose ``--out`` is a folder (``sm dance --out DIR``)
    creates that folder, with its parents. Raises a one-line :class:`OSError` (``sm`` exits with 2).
    """
    path = Path(path)
    parent = path.parent
    if not parent.is_dir():
        what = "is not a folder" if parent.exists() else "does not exist"
        raise FileNotFoundError(
            2, f"the folder {parent} {what}; create it first ({option} FILE must be in an existing folder)",
            str(path),
        )  # fmt: skip
    return check_writable(path)
