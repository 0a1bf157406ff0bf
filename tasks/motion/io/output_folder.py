"""Output folders: ``sm`` replaces and deletes only what it can prove it wrote.

Every command that writes into a folder (``--out DIR``: ``sm export-pretrained``, ``sm export-onnx``,
``sm export-web``, ``sm dance``, ``sm stream``, ``sm generate``, ``sm make-ego``) claims it first with
:func:`claim_output_folder`, before any work, then writes inside :func:`writing_outputs`:

- a missing folder is created, an empty one taken;
- a folder holding only the command's own earlier output is taken again. That output is what the
  manifest :data:`MANIFEST` lists, and only as far as the folder still proves it: the manifest must name
  the command and carry this user's signature (an HMAC-SHA256 under a key kept in the project's cache
  folder, :func:`output_key`), and a listed file counts only while it is a regular file (not a link) of
  the size and SHA-256 recorded when the command wrote it, a listed folder only while it is a real folder.
  A planted, edited or copied manifest, or a file changed since, claims nothing;
- any other non-empty folder (``--out .`` in a project, a folder of the user's files) is refused with one
  line naming it and an entry it holds, unless ``--overwrite`` is given; even then only the command's own
  file names are written and nothing is deleted; the user's files are not claimed by the new manifest.

:func:`writing_outputs` records the names before the first file is written and, when its block ends
(also on an error), the size and hash of each file the block wrote. A command that replaces its output
as a whole (``replaces=True``: an ONNX or pretrained export) then removes the files of the output it
replaced that it did not write again, and only those.

A command told to write one named file and files beside it (``sm dance --out FILE.npz`` also writes
``FILE.bvh``, ``FILE.glb``, ...) checks those others with :func:`claim_output_files`: an existing one is
refused unless ``--overwrite`` is given (the named file itself was asked for). Names given on the command
line (``--name``) are plain file names (:func:`~.option_types.file_name_option`). The files themselves
are written atomically (:mod:`skeleton_mamba.io.atomic`); a command's one output *file* goes into an existing
folder (:func:`output_file`).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import secrets
import stat
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from os import PathLike
from pathlib import Path

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.atomic import atomic_open, check_writable
from skeleton_mamba.io.bounded_read import read_json
from skeleton_mamba.tasks.motion.io.cache import default_cache_root, file_sha256
from skeleton_mamba.tasks.motion.io.option_types import is_plain_name

__all__ = [
    "MANIFEST",
    "OVERWRITE_HELP",
    "claim_output_files",
    "claim_output_folder",
    "output_file",
    "output_key",
    "verified_outputs",
    "writing_outputs",
]

MANIFEST = ".sm-output.json"
OVERWRITE_HELP = (
    "write into --out even when it holds files this command did not write (its own file names are "
    "replaced, nothing is deleted)"
)
FOLDER = {"folder": True}  # a manifest entry for a sub-folder the command created (make-ego's samples/)
_KEY_FILE = "output-key"


def output_key() -> bytes:
    """This user's key for signing manifests: 32 random bytes in ``<cache root>/output-key`` (mode 0600),
    created on first use (by one process: the file appears whole, through a hard link)."""
    path = default_cache_root() / _KEY_FILE
    for _ in range(2):
        try:
            key = bytes.fromhex(path.read_text(encoding="ascii").strip())
        except (OSError, ValueError):
            key = b""
        if len(key) == 32:
            return key
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{_KEY_FILE}-{os.getpid()}")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(secrets.token_hex(32) + "\n")
        try:
            if path.exists():  # unreadable or damaged: replaced (its manifests then claim nothing)
                os.replace(tmp, path)
            else:
                os.link(tmp, path)  # fails when another process created it meanwhile: read theirs
        except FileExistsError:
            pass
        finally:
            tmp.unlink(missing_ok=True)
    raise OSError(f"{path}: cannot create the key that signs output manifests")


def _signature(command: str, files: dict) -> str:
    message = json.dumps({"command": command, "files": files}, sort_keys=True).encode()
    return hmac.new(output_key(), message, hashlib.sha256).hexdigest()


def _stat(path: Path) -> os.stat_result | None:
    try:
        return path.lstat()
    except OSError:
        return None


def _proves(path: Path, entry: object) -> bool:
    """Whether ``path`` still is what the manifest ``entry`` recorded (module docstring)."""
    info = _stat(path)
    if info is None or not isinstance(entry, dict):
        return False
    if entry == FOLDER:
        return stat.S_ISDIR(info.st_mode)
    if not stat.S_ISREG(info.st_mode) or entry.get("size") != info.st_size:
        return False
    digest = entry.get("sha256")
    return isinstance(digest, str) and hmac.compare_digest(digest, file_sha256(path))


def _manifest(folder: Path, command: str) -> dict | None:
    """The entries of ``command``'s signed manifest in ``folder``, or None (no manifest, another
    command's, unreadable, or not signed by this user's key)."""
    path = folder / MANIFEST
    info = _stat(path)
    if info is None or not stat.S_ISREG(info.st_mode):
        return None
    try:
        record = read_json(path, max_bytes=4 << 20, what="output manifest", error=InputError)
    except InputError:
        return None
    if not isinstance(record, dict) or record.get("command") != command:
        return None
    files, signature = record.get("files"), record.get("signature")
    if not isinstance(files, dict) or not isinstance(signature, str):
        return None
    if not hmac.compare_digest(signature, _signature(command, files)):
        return None
    return files


def verified_outputs(folder: str | os.PathLike[str], command: str) -> dict[str, dict]:
    """The entries of ``folder`` that ``command`` provably wrote there (name -> manifest entry)."""
    folder = Path(folder)
    files = _manifest(folder, command) or {}
    proven = {name: entry for name, entry in files.items() if is_plain_name(name)}
    return {name: entry for name, entry in proven.items() if _proves(folder / name, entry)}


def claim_output_folder(
    folder: str | os.PathLike[str], command: str, files: Iterable[str], *, overwrite: bool = False
) -> Path:
    """Check, before any work, that ``command`` may write ``files`` (names inside ``folder``) into
    ``folder`` (module docstring); nothing is created yet (:func:`writing_outputs` does). Returns the
    folder.

    Raises:
        InputError: ``folder`` is a file; or it is not empty, not only the command's proven earlier
            output, and ``overwrite`` is not given.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder}: is a file (a folder is expected)")
    for name in files:
        if not is_plain_name(name):
            raise InputError(f"{name!r}: not a plain file name inside {folder}")
    entries = sorted(os.listdir(folder)) if folder.is_dir() else []
    ours = set(verified_outputs(folder, command)) | {MANIFEST} if entries else set()
    foreign = [e for e in entries if e not in ours]
    if foreign and not overwrite:
        raise InputError(
            f"{folder}: not empty and not an earlier output of {command} (it holds {len(entries)} entries, "
            f"e.g. {foreign[0]!r}); choose a new folder, or pass --overwrite to write into it anyway"
        )
    return folder


def _identity(path: Path) -> tuple[int, ...] | None:
    info = _stat(path)
    return None if info is None else (info.st_dev, info.st_ino, info.st_mtime_ns, info.st_size, info.st_mode)


def _write_manifest(folder: Path, command: str, files: dict) -> None:
    record = {"command": command, "files": files, "signature": _signature(command, files)}
    with atomic_open(folder / MANIFEST, "w", encoding="utf-8") as f:
        f.write(json.dumps(record, indent=2, sort_keys=True) + "\n")


@contextmanager
def writing_outputs(
    folder: str | os.PathLike[str], command: str, files: Iterable[str], *, replaces: bool = False
) -> Iterator[Path]:
    """Create ``folder`` (after :func:`claim_output_folder`) and record ``command``'s outputs in its
    manifest: the names before the block, what the block wrote when it ends (module docstring). A folder it
    created is removed again when the block fails before writing anything.

    Args:
        files: the names the block may write (a superset is fine: only what it wrote is recorded).
        replaces: the block's output replaces the earlier one as a whole; on success, the earlier
            output's files it did not write again are removed.
    """
    folder = Path(folder)
    created = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    earlier = verified_outputs(folder, command)
    names = set(files) | set(earlier)
    before = {name: _identity(folder / name) for name in names}
    _write_manifest(folder, command, {**earlier, **{n: {"pending": True} for n in set(files) - set(earlier)}})
    succeeded = False
    try:
        yield folder
        succeeded = True
    finally:
        if created and not succeeded and folder.is_dir() and set(os.listdir(folder)) <= {MANIFEST}:
            (folder / MANIFEST).unlink(missing_ok=True)  # failed before its first file: nothing left behind
            folder.rmdir()
        elif folder.is_dir():  # a command may remove a folder it created for nothing (make-ego)
            _seal(folder, command, names, before, earlier, remove=replaces and succeeded)


def _seal(
    folder: Path, command: str, names: set[str], before: dict, earlier: dict[str, dict], remove: bool
) -> None:
    """Record what :func:`writing_outputs`' block wrote (``before``: the entries' identities before it);
    ``remove``: the earlier output's files not written again are removed."""
    recorded: dict[str, dict] = {}
    for name in sorted(names):
        path, now = folder / name, _identity(folder / name)
        if now is None:
            continue
        if now != before[name]:  # written by the block (created, replaced or changed)
            if stat.S_ISREG(now[4]):
                recorded[name] = {"size": now[3], "sha256": file_sha256(path)}
            elif stat.S_ISDIR(now[4]) and before[name] is None:
                recorded[name] = dict(FOLDER)
            elif stat.S_ISDIR(now[4]) and name in earlier:
                recorded[name] = earlier[name]
        elif name in earlier:
            if remove and earlier[name] != FOLDER:
                path.unlink()  # the replaced output's file, proven ours, not written again
            else:
                recorded[name] = earlier[name]
    _write_manifest(folder, command, recorded)


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
