"""onnxruntime-web for the browser dancer page: the npm package, pinned and checked, read at export time.

The repository vendors none of it (its one wasm build is 15 MB). ``sm export-web`` reads the npm tarball
``onnxruntime-web-VERSION.tgz`` (MIT, Microsoft; its ``package.json`` names the licence, the text is
:data:`LICENCE_FILE` beside this module) as :mod:`.npm_tarball` reads a pinned package: a file the user names
(``--ort-web``), else the one in the cache folder, else one that ``npm pack`` fetches into the cache. Its
SHA-512 must be the npm registry's integrity of :data:`VERSION`.

From it the page takes three files: ``dist/ort.wasm.bundle.min.mjs`` (the wasm-only ES module with its
emscripten glue inside: nothing else to import on one thread), ``dist/ort-wasm-simd-threaded.wasm`` (the
one wasm build, SIMD, threads when the page is cross-origin isolated) and the glue on its own,
``dist/ort-wasm-simd-threaded.mjs`` (24 kB), from which the threads' workers start.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from importlib.resources import files

from skeleton_mamba.tasks.stream.npm_tarball import NpmPin

__all__ = ["INTEGRITY", "LICENCE_FILE", "PIN", "VERSION", "OrtWeb", "cache_dir", "read_ort_web"]

VERSION = "1.31.1"
INTEGRITY = "sha512-5GeH+bWQ+HxM10z7erGlsWqryrwMbSvm/1tkIsKTT48g0fI19VXVVC435t4t7VsPdSQeS7NmuZPXrQ73k82URw=="
TARBALL_BYTES = 34_586_352  # the pinned tarball's size: anything else is refused before it is read
PIN = NpmPin("onnxruntime-web", VERSION, INTEGRITY, TARBALL_BYTES, "onnxruntime-web", "--ort-web")
MODULE = "package/dist/ort.wasm.bundle.min.mjs"
WASM = "package/dist/ort-wasm-simd-threaded.wasm"
GLUE = "package/dist/ort-wasm-simd-threaded.mjs"
LICENCE_FILE = "LICENSE-onnxruntime-web.txt"


@dataclass(frozen=True)
class OrtWeb:
    """The files of onnxruntime-web the page embeds, and the licence text."""

    module: bytes
    wasm: bytes
    glue: bytes
    licence: str


def cache_dir():
    """``$SM_CACHE/onnxruntime-web`` (default ``~/.cache/skeleton_mamba/onnxruntime-web``)."""
    return PIN.cache_dir()


def read_ort_web(tarball: str | os.PathLike[str] | None = None) -> OrtWeb:
    """The page's onnxruntime-web files from ``tarball`` (default: the cache, fetched by npm if missing).

    Raises:
        InputError: naming the tarball when it is missing, not the pinned release, or lacks a file.
    """
    module, wasm, glue = PIN.read((MODULE, WASM, GLUE), tarball)
    licence = files("skeleton_mamba.tasks.stream.web").joinpath(LICENCE_FILE).read_text(encoding="utf-8")
    return OrtWeb(module=module, wasm=wasm, glue=glue, licence=licence)
