"""The one bounded reader of the files the project parses: JSON files, and the text of YAML files.

Every JSON file the project reads (``config.json`` of a pretrained folder, a safetensors header, a metrics
file, a sample's ``meta.json``, a Kinetics clip, ...) goes through :func:`read_json`, and the text of every
YAML file (recipes, backbone files) through :func:`read_text`; both read with :func:`read_bytes`:

- only a **regular file** is read: a FIFO (which would block), a device (``/dev/zero`` never ends), a
  socket or a folder is refused from its ``fstat`` (a link is followed; a link loop is the OS's error);
  the file is opened without blocking, so a FIFO is refused rather than waited on;
- at most ``max_bytes`` are read (the file's size is checked first, and a file growing while it is read
  stops at the bound);
- JSON nests at most ``max_depth`` arrays / objects (checked on the text, without recursion, before it is
  parsed: brackets inside strings do not count);
- numbers are finite: ``NaN``, ``Infinity`` and numbers beyond a double (``1e400``) are refused, or read
  as ``None`` where the caller asks (``non_finite="null"``); integers have at most
  :data:`MAX_INT_DIGITS` digits.

A refusal raises ``error`` (the caller's error type; :class:`BoundedReadError` by default) with one line
naming the file, and for JSON the line and column. This module imports the standard library only, so the
backbone package (torch + einops) can use it.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
from os import PathLike
from typing import Any

__all__ = [
    "MAX_INT_DIGITS",
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "BoundedReadError",
    "check_json_depth",
    "parse_json",
    "read_bytes",
    "read_json",
    "read_text",
]

MAX_JSON_BYTES = 64 << 20  # a JSON file the project reads, unless its reader states its own bound
MAX_JSON_DEPTH = 64  # nested arrays / objects; the project's files nest fewer than 10
MAX_INT_DIGITS = 18  # every integer the project's files hold (counts, indices, seeds) fits an int64
_BRACKETS_OR_STRINGS = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]')
_NUMBERS_OR_STRINGS = re.compile(r'"(?:[^"\\]|\\.)*"|-?(?:Infinity|NaN)|-?\d[\d.eE+-]*')
_READ_BLOCK = 1 << 20


class BoundedReadError(ValueError):
    """A file refused by the bounded reader (the message names the file and what is wrong)."""


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def read_bytes(
    path: str | PathLike[str],
    *,
    max_bytes: int,
    what: str = "file",
    error: type[Exception] = BoundedReadError,
) -> bytes:
    """The content of the regular file ``path``, at most ``max_bytes`` bytes (module docstring).

    Raises:
        error: not a regular file, or larger than ``max_bytes`` (the message names ``path`` and ``what``).
        OSError: the file is missing or unreadable (its own ``path: reason``).

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "run.json"
        >>> _ = path.write_text('{"epoch": 3, "scores": [0.5, 1.5]}')
        >>> read_bytes(path, max_bytes=1024)
        b'{"epoch": 3, "scores": [0.5, 1.5]}'
        >>> read_bytes(path, max_bytes=10, what="run record")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        skeleton_mamba.io.bounded_read.BoundedReadError: ...run.json: 34 bytes, more than a run record's 10
    """
    name = os.fspath(path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(name, flags)  # O_NONBLOCK: opening a FIFO returns at once instead of waiting for a writer
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise error(f"{name}: {_kind(info.st_mode)}, not a regular file (a {what} is expected)")
        if info.st_size > max_bytes:
            raise error(f"{name}: {info.st_size:,} bytes, more than a {what}'s {max_bytes:,}")
        chunks, total = [], 0
        while total <= max_bytes:
            chunk = os.read(fd, min(_READ_BLOCK, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
        if total > max_bytes:
            raise error(f"{name}: grew beyond a {what}'s {max_bytes:,} bytes while it was read")
        return b"".join(chunks)
    finally:
        os.close(fd)


def read_text(
    path: str | PathLike[str],
    *,
    max_bytes: int,
    what: str = "file",
    error: type[Exception] = BoundedReadError,
) -> str:
    """:func:`read_bytes` decoded as UTF-8 (a leading byte-order mark dropped).

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "run.json"
        >>> _ = path.write_text('{"epoch": 3, "scores": [0.5, 1.5]}')
        >>> read_text(path, max_bytes=1024)[:10]
        '{"epoch": '
    """
    data = read_bytes(path, max_bytes=max_bytes, what=what, error=error)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise error(f"{os.fspath(path)}: not UTF-8 text (byte {err.start}: {err.reason})") from None


def _line_column(text: str, index: int) -> str:
    line = text.count("\n", 0, index) + 1
    return f"{line}:{index - (text.rfind(chr(10), 0, index) + 1) + 1}"


def _first_non_finite(text: str) -> str:
    """``line:column`` of the first NaN, Infinity or overflowing number of ``text`` (strings skipped): the
    one the parser, reading left to right, refused."""
    for match in _NUMBERS_OR_STRINGS.finditer(text):
        token = match.group()
        try:
            finite = token[0] == '"' or math.isfinite(float(token.replace("Infinity", "inf")))
        except ValueError:
            continue
        if not finite:
            return _line_column(text, match.start())
    return "?"


def check_json_depth(
    text: str, source: str, max_depth: int, error: type[Exception] = BoundedReadError
) -> None:
    """Refuse ``text`` nesting more than ``max_depth`` arrays / objects (brackets in strings do not count).

    Examples:
        >>> check_json_depth('[[1], "[[["]', "ok.json", max_depth=2)  # brackets in strings do not count
        >>> check_json_depth("[[[1]]]", "deep.json", max_depth=2)
        Traceback (most recent call last):
        ...
        skeleton_mamba.io.bounded_read.BoundedReadError: deep.json:1:3: nested more than 2 levels deep
    """
    depth = 0
    for match in _BRACKETS_OR_STRINGS.finditer(text):
        token = match.group()
        if token in "[{":
            depth += 1
            if depth > max_depth:
                where = _line_column(text, match.start())
                raise error(f"{source}:{where}: nested more than {max_depth} levels deep")
        elif token in "]}":
            depth -= 1


def parse_json(
    text: str | bytes,
    source: str,
    *,
    max_depth: int = MAX_JSON_DEPTH,
    non_finite: str = "refuse",
    error: type[Exception] = BoundedReadError,
) -> Any:
    """JSON ``text`` parsed within the bounds of the module docstring; ``source`` names it in errors.

    ``non_finite``: ``"refuse"`` (default) or ``"null"`` (``NaN``, ``Infinity`` and overflowing numbers
    read as ``None``).

    Examples:
        >>> parse_json('{"fps": 30, "joints": [1, 2]}', "inline")
        {'fps': 30, 'joints': [1, 2]}
        >>> parse_json('[1.0, NaN]', "inline", non_finite="null")
        [1.0, None]
        >>> parse_json('[1.0, NaN]', "inline")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        skeleton_mamba.io.bounded_read.BoundedReadError: inline...NaN...
    """
    if non_finite not in ("refuse", "null"):
        raise ValueError(f"non_finite must be 'refuse' or 'null', got {non_finite!r}")
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8-sig")
        except UnicodeDecodeError as err:
            raise error(f"{source}: not UTF-8 text (byte {err.start}: {err.reason})") from None
    check_json_depth(text, source, max_depth, error)

    def refuse(token: str) -> None:
        if non_finite == "null":
            return None
        shown = token if len(token) <= 30 else token[:27] + "..."
        raise error(
            f"{source}:{_first_non_finite(text)}: {shown} is not a finite number (JSON's numbers are finite)"
        )

    def parse_float(token: str) -> float | None:
        value = float(token)
        return value if math.isfinite(value) else refuse(token)

    def parse_int(token: str) -> int | float | None:
        digits = len(token.lstrip("-"))
        if digits > MAX_INT_DIGITS:
            raise error(f"{source}: an integer of {digits} digits (at most {MAX_INT_DIGITS})")
        return int(token)

    try:
        return json.loads(text, parse_constant=refuse, parse_float=parse_float, parse_int=parse_int)
    except json.JSONDecodeError as err:
        raise error(f"{source}:{err.lineno}:{err.colno}: not valid JSON ({err.msg})") from None
    except RecursionError:  # not reached after the depth check; kept so no traceback can escape
        raise error(f"{source}: nested too deeply") from None


def read_json(
    path: str | PathLike[str],
    *,
    max_bytes: int = MAX_JSON_BYTES,
    max_depth: int = MAX_JSON_DEPTH,
    non_finite: str = "refuse",
    what: str = "JSON file",
    error: type[Exception] = BoundedReadError,
) -> Any:
    """The JSON file ``path``, read with :func:`read_bytes` and parsed with :func:`parse_json`.

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "run.json"
        >>> _ = path.write_text('{"epoch": 3, "scores": [0.5, 1.5]}')
        >>> read_json(path)
        {'epoch': 3, 'scores': [0.5, 1.5]}
    """
    data = read_bytes(path, max_bytes=max_bytes, what=what, error=error)
    return parse_json(data, os.fspath(path), max_depth=max_depth, non_finite=non_finite, error=error)
