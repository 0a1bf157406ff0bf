"""A pinned npm package the browser page embeds (onnxruntime-web, three-vrm), read at export time and checked.

The repository vendors neither. ``sm export-web`` reads the package's npm tarball: a file the user names (an
option such as ``--ort-web``), else the one in the cache folder (``$SM_CACHE``, default
``~/.cache/skeleton_mamba``), else one that ``npm pack`` fetches into the cache (the only network access, at
export time; the page makes none). The tarball must have the pinned size before a byte is read, and its
SHA-512, hashed while it is read (never more than its size plus one chunk), must be the npm registry's
integrity of the pinned version; only then is it opened and the page's files taken from it.
"""

from __future__ import annotations

import base64
import hashlib
import io
import os
import shutil
import subprocess
import tarfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from skeleton_mamba.errors import InputError

__all__ = ["NpmPin", "cache_root"]

NPM_TIMEOUT_S = 300


def cache_root() -> Path:
    """``$SM_CACHE`` (default ``~/.cache/skeleton_mamba``)."""
    return Path(os.environ.get("SM_CACHE") or Path.home() / ".cache" / "skeleton_mamba")


def _integrity(digest: bytes) -> str:
    """npm's integrity string of a SHA-512 ``digest``."""
    return "sha512-" + base64.b64encode(digest).decode("ascii")


def _read_hashed(path: Path, limit: int, chunk: int = 1 << 20) -> tuple[bytes, bytes]:
    """The bytes of ``path`` and their SHA-512 digest, hashed as they are read in chunks, never more than
    ``limit`` + one chunk (a file that grew after its size was checked is not read whole)."""
    digest, parts, size = hashlib.sha512(), [], 0
    with path.open("rb") as f:
        while size <= limit and (part := f.read(chunk)):
            digest.update(part)
            parts.append(part)
            size += len(part)
    return b"".join(parts), digest.digest()


@dataclass(frozen=True)
class NpmPin:
    """One npm package at one version: its tarball's size and the registry's SHA-512 integrity.

    Attributes:
        package: the npm name (``onnxruntime-web``, ``@pixiv/three-vrm``).
        version, integrity, size: the pinned release.
        folder: the cache folder's name; option: the command-line option naming a tarball (messages).
    """

    package: str
    version: str
    integrity: str
    size: int
    folder: str
    option: str

    @property
    def tarball(self) -> str:
        """npm pack's file name: ``<name without @, / as ->-<version>.tgz``."""
        return f"{self.package.lstrip('@').replace('/', '-')}-{self.version}.tgz"

    @property
    def spec(self) -> str:
        return f"{self.package}@{self.version}"

    def cache_dir(self) -> Path:
        return cache_root() / self.folder

    def _npm_pack(self, folder: Path) -> Path:
        """``npm pack PACKAGE@VERSION`` into ``folder``; the tarball's path."""
        npm = shutil.which("npm")
        if npm is None:
            raise InputError(
                f"{self.package} {self.version} is not in {folder} and npm is not on PATH: install Node.js, "
                f"or download {self.tarball} (npm pack {self.spec}) and pass {self.option} FILE"
            )
        folder.mkdir(parents=True, exist_ok=True)
        command = [npm, "pack", self.spec, "--pack-destination", str(folder)]
        proc = subprocess.run(command, capture_output=True, text=True, timeout=NPM_TIMEOUT_S)
        if proc.returncode != 0 or not (folder / self.tarball).is_file():
            last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            raise InputError(f"npm pack {self.spec} failed ({last}); pass {self.option} FILE instead")
        return folder / self.tarball

    def read(self, members: Sequence[str], tarball: str | os.PathLike[str] | None = None) -> list[bytes]:
        """The files ``members`` of the pinned tarball (``tarball``, default: the cache, fetched by npm if
        missing), in that order.

        Raises:
            InputError: naming the tarball when it is missing, not the pinned release, or lacks a member.
        """
        path = Path(tarball) if tarball is not None else self.cache_dir() / self.tarball
        if tarball is None and not path.is_file():
            path = self._npm_pack(path.parent)
        if not path.is_file():
            raise InputError(f"{path}: no such file (the npm tarball {self.tarball})")
        what = f"not the npm tarball of {self.package} {self.version}"
        if path.stat().st_size != self.size:
            raise InputError(f"{path}: {what} ({path.stat().st_size} bytes, not {self.size})")
        data, digest = _read_hashed(path, self.size)
        if len(data) != self.size or _integrity(digest) != self.integrity:
            raise InputError(f"{path}: {what} (its SHA-512 differs)")
        try:
            with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as archive:
                return [archive.extractfile(archive.getmember(n)).read() for n in members]
        except (KeyError, tarfile.TarError, OSError, AttributeError) as err:
            raise InputError(f"{path}: cannot read {', '.join(members)} from it ({err})") from err
