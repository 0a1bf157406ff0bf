"""three-vrm for the dancer page's VRM characters (``sm export-web --rig avatar.vrm``): the npm package
``@pixiv/three-vrm``, pinned and checked, read at export time as :mod:`.npm_tarball` reads a pinned package (a
file the user names with ``--three-vrm``, else the cache, else ``npm pack``).

The page takes its ES module ``lib/three-vrm.module.min.js`` (it imports only ``three``: three.js r170 of the
page) and registers its ``VRMLoaderPlugin`` with GLTFLoader, so a VRM 0.x or 1.0 avatar is drawn with its own
materials (MToon) and its spring bones (hair, clothes) move; the licence (MIT, pixiv Inc.) is the package's
``LICENSE``, written beside the page.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from skeleton_mamba.tasks.stream.npm_tarball import NpmPin

__all__ = ["LICENCE_FILE", "PIN", "VERSION", "ThreeVrm", "read_three_vrm"]

VERSION = "3.5.5"
INTEGRITY = "sha512-RPXy7jYAXs704NIpZlosB0U2ENu21G9DrqGWdQgRe8dShaCo1ugpj+6BVPRCy91nt+MPMA96j5rbsSzEl0HlQA=="
TARBALL_BYTES = 576_823
PIN = NpmPin("@pixiv/three-vrm", VERSION, INTEGRITY, TARBALL_BYTES, "three-vrm", "--three-vrm")
MODULE = "package/lib/three-vrm.module.min.js"
LICENCE = "package/LICENSE"
LICENCE_FILE = "LICENSE-three-vrm.txt"


@dataclass(frozen=True)
class ThreeVrm:
    """three-vrm's ES module and its licence text."""

    module: bytes
    licence: str


def read_three_vrm(tarball: str | os.PathLike[str] | None = None) -> ThreeVrm:
    """The page's three-vrm module from ``tarball`` (default: the cache, fetched by npm if missing).

    Raises:
        InputError: naming the tarball when it is missing, not the pinned release, or lacks a file.
    """
    module, licence = PIN.read((MODULE, LICENCE), tarball)
    return ThreeVrm(module=module, licence=licence.decode("utf-8"))
