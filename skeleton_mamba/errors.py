"""The project's error types and the one-line messages ``sm`` prints for expected failures.

Policy (applied by ``skeleton_mamba.tasks.training.cli.main`` to every command):

- an expected failure (a :class:`SkeletonMambaError`, or an :class:`OSError` such as a missing or
  unwritable path, or a directory where a file belongs) prints one line ``sm COMMAND: error: message``
  naming the file (argparse's form for a bad argument) and exits with status 2; one raised in a DataLoader
  worker process (which torch re-raises with the worker's traceback as its text) prints the same line;
- Ctrl-C prints ``sm COMMAND: interrupted`` and exits with status 130;
- anything else is a bug and keeps its traceback. ``SM_TRACEBACK=1`` shows the traceback of expected
  failures too.
"""

from __future__ import annotations

import errno
import os
import re
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
    text = str(err)
    original = _worker_original(text, type(err).__name__)
    if original is not None and isinstance(err, OSError) and not isinstance(err, SkeletonMambaError):
        parts = re.fullmatch(r"\[Errno (\d+)\] (.+?)(?:: '(.*)')?", original)  # str() of an OSError
        if parts is not None:  # rebuilt, for the ``path: reason`` form above
            return one_line_message(type(err)(int(parts[1]), parts[2], parts[3]))
    return original or text or type(err).__name__


# torch's ExceptionWrapper.reraise: "Caught DataFileError in DataLoader worker process 0.\nOriginal Traceback
# (most recent call last):\n ... \nskeleton_mamba.errors.DataFileError: MESSAGE\n"
_RERAISED = re.compile(r"Caught \w+ in [^\n]*\.\nOriginal Traceback \(most recent call last\):\n")


def _worker_original(text: str, type_name: str) -> str | None:
    """The original message of an exception torch re-raised from a DataLoader worker (or its pin-memory
    thread) with the worker's traceback as its text; None when ``text`` is not such a message.

    The traceback ends with the line ``package.module.TypeName: MESSAGE`` (the message may span lines);
    the last such line of the re-raised type is taken, else the traceback's last line.
    """
    if not _RERAISED.match(text):
        return None
    header = re.compile(rf"^(?:[\w.]+\.)?{re.escape(type_name)}: ", re.MULTILINE)
    starts = list(header.finditer(text))
    if starts:
        return text[starts[-1].end() :].strip() or type_name
    last = text.strip().splitlines()[-1]
    return re.sub(r"^[\w.]+: ", "", last, count=1) or type_name


def worker_ignores_ctrl_c() -> None:
    """Initializer of worker processes: Ctrl-C reaches the whole process group, but only the parent acts on
    it (it stops the workers), so workers print no traceback of their own."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
