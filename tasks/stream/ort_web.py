"""onnxruntime-web for the browser dancer page: the npm package, pinned and checked, read at export time.

The repository vendors none of it (its one wasm build is 15 MB). ``sm export-web`` reads the npm tarball
``onnxruntime-web-VERSION.tgz`` (MIT, Microsoft; its ``package.json`` names the licence, the text is
:data:`LICENCE_FILE` beside this module): a file the user names (``--ort-web``), else the one in the
cache folder, else one that ``npm pack`` fetches into the cache (the only network access, at export
time; the page makes none). Its SHA-512 must be the npm registry's integrity of :data:`VERSION`.

From it the page takes three files: ``dist/ort.wasm.bundle.min.mjs`` (the wasm-only ES module with its
emscripten glue inside: nothing else to import on one thread), ``dist/ort-wasm-simd-threaded.wasm`` (the
one wasm build, SIMD, threads when the page is cross-origin isolated) and the glue on its own,
``dist/ort-wasm-simd-threaded.mjs`` (24 kB), from which the threads' workers start.
"""

from __future__ import annotations

import base64
import hashlib
import io
import os
import shutil
import subprocess
import tarfile
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

from skeleton_mamba.tasks.motion.errors import InputError

__all__ = ["INTEGRITY", "LICENCE_FILE", "VERSION", "OrtWeb", "cache_dir", "read_ort_web"]

VERSION = "1.31.1"
INTEGRITY = "sha512-5GeH+bWQ+HxM10z7erGlsWqryrwMbSvm/1tkIsKTT48g0fI19VXVVC435t4t7VsPdSQeS7NmuZPXrQ73k82URw=="
TARBALL = f"onnxruntime-web-{VERSION}.tgz"
TARBALL_BYTES = 34_586_352  # the pinned tarball's size: anything else is refused before it is read
MODULE = "package/dist/ort.wasm.bundle.min.mjs"
WASM = "package/dist/ort-wasm-simd-threaded.wasm"
GLUE = "package/dist/ort-wasm-simd-threaded.mjs"
PAGE_FILES = (MODULE, WASM, GLUE)
LICENCE_FILE = "LICENSE-onnxruntime-web.txt"
NPM_TIMEOUT_S = 300


@dataclass(frozen=True)
class OrtWeb:
    """The two files of onnxruntime-web the page embeds, and the licence text."""

    module: bytes
    wasm: bytes
    glue: bytes
    licence: str


def cache_dir() -> Path:
    """``$SM_CACHE/onnxruntime-web`` (default ``~/.cache/skeleton_mamba/onnxruntime-web``)."""
    root = os.environ.get("SM_CACHE") or Path.home() / ".cache" / "skeleton_mamba"
    return Path(root) / "onnxruntime-web"


def _integrity(digest: bytes) -> str:
    """npm's integrity string of a SHA-512 ``digest``."""
    return "sha512-" + base64.b64encode(digest).decode("ascii")


def _read_hashed(path: Path, chunk: int = 1 << 20) -> tuple[bytes, bytes]:
    """The bytes of ``path`` and their SHA-512 digest, hashed as they are read in chunks, never more than
    :data:`TARBALL_BYTES` + one chunk (a file that grew after its size was checked is not read whole)."""
    digest, parts, size = hashlib.sha512(), [], 0
    with path.open("rb") as f:
        while size <= TARBALL_BYTES and (part := f.read(chunk)):
            digest.update(part)
            parts.append(part)
            size += len(part)
    return b"".join(parts), digest.digest()


def _npm_pack(folder: Path) -> Path:
    """``npm pack onnxruntime-web@VERSION`` into ``folder``; the tarball's path."""
    npm = shutil.which("npm")
    if npm is None:
        raise InputError(
            f"onnxruntime-web {VERSION} is not in {folder} and npm is not on PATH: install Node.js, or "
            f"download {TARBALL} (npm pack onnxruntime-web@{VERSION}) and pass --ort-web FILE"
        )
    folder.mkdir(parents=True, exist_ok=True)
    command = [npm, "pack", f"onnxruntime-web@{VERSION}", "--pack-destination", str(folder)]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=NPM_TIMEOUT_S)
    if proc.returncode != 0 or not (folder / TARBALL).is_file():
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise InputError(f"npm pack onnxruntime-web@{VERSION} failed ({last}); pass --ort-web FILE instead")
    return folder / TARBALL


def read_ort_web(tarball: str | os.PathLike[str] | None = None) -> OrtWeb:
    """The page's onnxruntime-web files from ``tarball`` (default: the cache, fetched by npm if missing).

    Raises:
        InputError: naming the tarball when it is missing, not the pinned release, or lacks a file.
    """
    path = Path(tarball) if tarball is not None else cache_dir() / TARBALL
    if tarball is None and not path.is_file():
        path = _npm_pack(path.parent)
    if not path.is_file():
        raise InputError(f"{path}: no such file (the npm tarball {TARBALL})")
    if path.stat().st_size != TARBALL_BYTES:
        raise InputError(
            f"{path}: not the npm tarball of onnxruntime-web {VERSION} ({path.stat().st_size} bytes, not "
            f"{TARBALL_BYTES})"
        )
    data, digest = _read_hashed(path)
    if len(data) != TARBALL_BYTES or _integrity(digest) != INTEGRITY:
        raise InputError(f"{path}: not the npm tarball of onnxruntime-web {VERSION} (its SHA-512 differs)")
    try:
        with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as archive:
            module, wasm, glue = (archive.extractfile(archive.getmember(n)).read() for n in PAGE_FILES)
    except (KeyError, tarfile.TarError, OSError) as err:
        raise InputError(f"{path}: cannot read {MODULE}, {WASM} and {GLUE} from it ({err})") from err
    licence = files("skeleton_mamba.tasks.stream.web").joinpath(LICENCE_FILE).read_text(encoding="utf-8")
    return OrtWeb(module=module, wasm=wasm, glue=glue, licence=licence)
