"""Atomic file writes: write a temporary file beside the target, rename it over the target on success.

An interruption (Ctrl-C, an exception, a full disk) leaves the old file intact and removes the
temporary one; a reader never sees a half-written file. The rename is :func:`os.replace`, atomic
within one file system, which is why the temporary file lives in the target's own folder.

The temporary name keeps the target's suffix (``.render.mp4`` -> ``.render.<random>.mp4``), so writers
that choose the format by extension (ffmpeg, PIL, ``np.save`` adding ``.npy``) behave as for the target.
The file gets the mode :func:`open` gives a new file (0666 less the umask), not the temporary file's 0600.
Every writer of the project goes through here: the backbone's ``save_pretrained`` and the toolkit's
commands; standard library only.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from os import PathLike
from pathlib import Path
from typing import IO, Any

__all__ = ["atomic_open", "atomic_path", "check_writable"]


def check_writable(path: str | PathLike[str]) -> Path:
    """``path`` as a :class:`Path` after checking it can become a file; raises a one-line :class:`OSError`.

    Raises:
        IsADirectoryError: ``path`` is an existing directory.
        NotADirectoryError: a file stands where one of its folders should be.
        PermissionError: its folder is not writable.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(21, "Is a directory", str(path))
    for folder in path.parents:
        if folder.exists():
            if not folder.is_dir():
                raise NotADirectoryError(20, "Not a directory (a file is in the way)", str(folder))
            break
    path.parent.mkdir(parents=True, exist_ok=True)
    if not os.access(path.parent, os.W_OK):
        raise PermissionError(13, "Permission denied", str(path.parent))
    return path


def _new_file_mode() -> int:
    """The mode :func:`open` gives a new file: 0666 less the process umask."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


@contextlib.contextmanager
def atomic_path(path: str | PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on a clean exit it is renamed to ``path``.

    Example::

        with atomic_path(out) as tmp:
            np.save(tmp, array)          # tmp ends in ``out``'s suffix

    On any exception (``KeyboardInterrupt`` included) the temporary file is removed and ``path`` keeps
    its old content. The parent folder is created when missing.
    """
    path = check_writable(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix or ".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, _new_file_mode())  # mkstemp's 0600 would make every output private
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_open(path: str | PathLike[str], mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """:func:`open` for writing, atomically: the data reaches ``path`` only when the block ends cleanly.

    ``mode`` is ``"w"`` or ``"wb"``; ``kwargs`` go to :func:`open` (``encoding``, ``newline``). The file
    is flushed and fsynced before the rename.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes whole files: mode 'w' or 'wb', not {mode!r}")
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as handle:
        yield handle
        handle.flush()
        os.fsync(handle.fileno())
