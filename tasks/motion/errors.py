"""The project's error types and the one-line messages ``sm`` prints for expected failures.

Policy (applied by ``skeleton_mamba.tasks.training.cli.main`` to every command):

- an expected failure (a :class:`SkeletonMambaError`, or an :class:`OSError` such as a missing or
  unwritable path, or a directory where a file belongs) prints one line ``sm COMMAND: message`` naming
  the file and exits with status 2;
- Ctrl-C prints ``sm COMMAND: interrupted`` and exits with status 130;
- anything else is a bug and keeps its traceback. ``SM_TRACEBACK=1`` shows the traceback of expected
  failures too.
"""

from __future__ import annotations

import errno
import os
import signal

__all__ = [
    "CheckpointError",
    "DatasetNotFoundError",
    "InputError",
    "NonFiniteLossError",
    "SkeletonMambaError",
    "expected_failure",
    "one_line_message",
    "worker_ignores_ctrl_c",
]


class SkeletonMambaError(Exception):
    """Base of the project's expected failures: bad input, missing data, refused checkpoints.

    The message names the file (or sample) and says what is wrong; ``sm`` prints it and exits with 2.
    """


class DatasetNotFoundError(SkeletonMambaError, FileNotFoundError):
    """A data module's files are missing.

    The message says where the data is expected and which command (``sm prepare ...``) builds it;
    ``sm fit|validate|test|predict`` prints it and exits with status 2.
    """


class DataFileError(SkeletonMambaError, ValueError):
    """A data file is malformed or holds values the project refuses (NaN, Inf, absurd counts or rates).

    The message names the file and where in it (line, frame, key). Every reader's own error type
    (``SkeletonFileError``, ``KineticsFileError``, ``AnnotationFileError``, ``BvhError``,
    ``MotionFileError``, ...) derives from it, so a command can catch the whole class at once.
    """


class InputError(SkeletonMambaError, ValueError):
    """A command's input is unusable: a file's content, or an argument about files (the message names it)."""


class CheckpointError(SkeletonMambaError, ValueError):
    """A checkpoint is refused: remote, not a plain-data checkpoint, or naming a foreign class."""


class NonFiniteLossError(SkeletonMambaError, FloatingPointError):
    """The training loss became NaN or infinite; the message names the step and the batch's samples."""


class RandomWeightsWarning(UserWarning):
    """A part of a network starts from random instead of pretrained weights (moot when a checkpoint's
    weights are loaded over it: :func:`~skeleton_mamba.tasks.training.checkpoints.load_module_and_checkpoint`
    silences it)."""


def expected_failure(err: BaseException | None) -> BaseException | None:
    """The expected failure behind ``err``: itself or an explicit cause (jsonargparse wraps with ``from``).

    A :class:`SkeletonMambaError` anywhere in the chain wins over an :class:`OSError`; ``None`` when the
    chain holds neither (a bug, which keeps its traceback). Implicit contexts (an error raised while
    handling another) are not followed, so a bug in an ``except`` block is never hidden behind the error it
    was handling.
    """
    chain: list[BaseException] = []
    while err is not None and all(err is not seen for seen in chain):
        chain.append(err)
        err = err.__cause__
    for kinds in (SkeletonMambaError, OSError):
        for item in chain:
            if isinstance(item, kinds):
                return item
    return None


def one_line_message(err: BaseException) -> str:
    """``err`` as the message ``sm`` prints: OS errors as ``path: reason``, others as their text."""
    if isinstance(err, OSError) and not isinstance(err, SkeletonMambaError) and err.strerror:
        reason = err.strerror
        if isinstance(err, IsADirectoryError) or err.errno == errno.EISDIR:
            reason = "is a directory (a file path is expected)"
        elif isinstance(err, FileExistsError) and err.filename and not os.path.isdir(err.filename):
            reason = "is a file (a folder is expected)"
        elif isinstance(err, PermissionError):
            reason = "permission denied (not writable or not readable)"
        names = [os.fspath(n) for n in (err.filename, err.filename2) if n is not None]
        return f"{' -> '.join(map(str, names))}: {reason}" if names else reason
    return str(err) or type(err).__name__


def worker_ignores_ctrl_c() -> None:
    """Initializer of worker processes: Ctrl-C reaches the whole process group, but only the parent acts on
    it (it stops the workers), so workers print no traceback of their own."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
