"""``sm view MOTION [MOTION ...] [--music FILE] [--metrics demo.json] [--overlay] [--units U|--scale S]
--out view.html``.

Writes ONE self-contained HTML page (opens from disk, no network): three.js r170, its OrbitControls and
GLTFLoader (the npm package ``three``, MIT, bundled in :mod:`.viewer`) as data-URI modules, each motion as its
glTF binary (:mod:`skeleton_mamba.tasks.motion.formats.gltf`, base64; a character, :mod:`.character`, as its
own file: its meshes move), the music as a data-URI ``<audio>`` element. The page draws the skeletons on a
ground grid with shadows, fits an orbit camera to the whole motion, and has play / pause / scrub / speed; with
music the audio element is the clock and a scrub moves it. Several motions stand side by side (or
``--overlay``), named and coloured, with the metrics of a ``demo.json`` listed by their full names (nested
objects as ``scores.dance.mpjpe_m``, whole numbers as such, booleans as yes / no, short texts as they are) and
the scale each file was read with when it is not metres by its format
(:mod:`skeleton_mamba.tasks.motion.formats.units`). Motions are read by
:mod:`skeleton_mamba.tasks.motion.formats.motion_reader` (our ``.glb`` exports too). ``window.smViewer``
exposes the clock, ``seek(t)``, the camera, the projection of a world point to canvas pixels, each motion's
root and joints in world space.

Hostile input cannot break the page: the embedded data is strict JSON (:func:`script_json`: a non-finite
metric is written as ``null``, every ``<``, ``>`` and ``&`` of every string as a ``\\u`` escape, so no name,
key or value can close the ``<script>`` element or open a comment, and U+2028 / U+2029 escaped too), the
title is HTML-escaped, the metrics file is read by the project's bounded JSON reader (at most
:data:`MAX_METRICS_BYTES`), and the music must be audio the project's reader accepts, at most
:data:`MAX_MUSIC_BYTES` (it is embedded whole).
"""

from __future__ import annotations

import base64
import html
import json
import math
import re
import sys
from collections.abc import Sequence
from importlib.resources import files
from os import PathLike
from pathlib import Path

import numpy as np

from skeleton_mamba.errors import InputError, one_line_message
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.io.bounded_read import read_bytes, read_json
from skeleton_mamba.tasks.motion.commands.view_args import build_parser
from skeleton_mamba.tasks.motion.formats.gltf import SkeletonMotion, glb_bytes
from skeleton_mamba.tasks.motion.formats.motion_reader import load_skeleton_motion
from skeleton_mamba.tasks.motion.formats.units import METRES
from skeleton_mamba.tasks.motion.io.output_folder import output_file
from skeleton_mamba.tasks.motion.music.audio_io import probe_audio
from skeleton_mamba.tasks.motion.render.character import Character, read_character

__all__ = [
    "MAX_METRICS_BYTES",
    "MAX_MUSIC_BYTES",
    "MAX_TEXT",
    "listed_metrics",
    "main",
    "script_json",
    "three_modules",
    "write_view",
]

MAX_METRICS_BYTES = 16 << 20  # a metrics file (a demo's demo.json is a few KiB)
MAX_MUSIC_BYTES = 128 << 20  # music embedded in the page: 12 minutes of CD-quality WAV
MAX_TEXT = 60  # longer texts of a metrics file (paths, descriptions) are not listed
# Characters that could end the <script> element or start a comment inside it, or end a JS line
_SCRIPT_ESCAPES = {"<": "\\u003c", ">": "\\u003e", "&": "\\u0026"}

_AUDIO_TYPES = {
    ".wav": "audio/wav",
    ".mp3": "audio/mpeg",
    ".ogg": "audio/ogg",
    ".opus": "audio/ogg",
    ".flac": "audio/flac",
}


def _data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def script_json(data: object) -> str:
    """``data`` as strict JSON (``NaN`` / ``Infinity`` refused) safe inside a ``<script>`` element: every
    ``<``, ``>``, ``&``, U+2028 and U+2029 (which can only occur inside JSON strings) as its ``\\u`` escape,
    which ``JSON.parse`` reads back unchanged."""
    text = json.dumps(data, allow_nan=False, ensure_ascii=True)  # ASCII: U+2028 / U+2029 escaped already
    for char, escape in _SCRIPT_ESCAPES.items():
        text = text.replace(char, escape)
    return text


def listed_metrics(metrics: dict | None, prefix: str = "") -> dict[str, float | int | str | None]:
    """The entries of a metrics dict the page lists, by full dotted name: numbers (whole numbers as ints;
    NaN, infinities and JSON ``null`` as ``None``, shown as ``null``), booleans as ``yes`` / ``no``, texts of
    at most :data:`MAX_TEXT` characters; nested dicts at any depth (``scores.dance.mpjpe_m``); lists and
    longer texts are left out."""
    out: dict[str, float | int | str | None] = {}
    for key, value in (metrics or {}).items():
        name = f"{prefix}{key}"
        if isinstance(value, bool):
            out[name] = "yes" if value else "no"
        elif isinstance(value, int):
            out[name] = value
        elif isinstance(value, float):
            out[name] = value if math.isfinite(value) else None
        elif value is None:
            out[name] = None
        elif isinstance(value, str) and len(value) <= MAX_TEXT:
            out[name] = value
        elif isinstance(value, dict):
            out.update(listed_metrics(value, f"{name}."))
    return out


def three_modules() -> dict[str, str]:
    """The import map's modules of a page (``__THREE__``, ``__ORBIT__``, ``__GLTF__``, ``__BGU__``): three.js
    r170, its OrbitControls, GLTFLoader and the BufferGeometryUtils GLTFLoader imports, as data URIs.

    GLTFLoader imports ``'../utils/BufferGeometryUtils.js'``, a path a data-URI module cannot resolve: the
    page's import map names it ``sm-bgu`` and the one import is rewritten to that name here."""
    assets = files("skeleton_mamba.tasks.motion.render.viewer")

    def module(name: str, replace: tuple[str, str] | None = None) -> str:
        text = assets.joinpath(name).read_text(encoding="utf-8")
        if replace is not None:
            if text.count(replace[0]) != 1:
                raise RuntimeError(f"{name}: expected one {replace[0]} to rewrite")
            text = text.replace(*replace)
        return _data_uri(text.encode("utf-8"), "text/javascript")

    return {
        "__THREE__": module("three.module.min.js"),
        "__ORBIT__": module("OrbitControls.js"),
        "__GLTF__": module("GLTFLoader.js", ("'../utils/BufferGeometryUtils.js'", "'sm-bgu'")),
        "__BGU__": module("BufferGeometryUtils.js"),
    }


def write_view(
    motions: Sequence[tuple[str, SkeletonMotion | Character]],
    out: str | PathLike[str],
    music: str | PathLike[str] | None = None,
    metrics: dict | str | PathLike[str] | None = None,
    overlay: bool = False,
) -> Path:
    """Write the viewer page for named motions (module docstring), atomically; returns its path.

    Args:
        motions: (name, motion) pairs, drawn left to right (all at the origin with ``overlay``); a
            :class:`~.character.Character` is drawn with its own meshes, playing its first animation.
        out: the ``.html`` to write.
        music: an audio file played in sync from the motions' first frame.
        metrics: a dict or the path of a JSON file (e.g. a demo's ``demo.json``), listed by
            :func:`listed_metrics`.
        overlay: draw every motion at its own place instead of side by side.
    """
    out = Path(out)
    if not motions:
        raise ValueError(f"{out}: no motion to view")
    if isinstance(metrics, (str, PathLike)):
        path = Path(metrics)
        bounds = {"max_bytes": MAX_METRICS_BYTES, "non_finite": "null"}
        metrics = read_json(path, **bounds, what="metrics file", error=InputError)
        if not isinstance(metrics, dict):
            raise InputError(f"{path}: expected a JSON object of metrics")
    entries = [  # checked and written first: the spacing below reads only checked motions
        {"name": name, "character": base64.b64encode(m.data).decode("ascii"), "hips": m.hips}
        if isinstance(m, Character)
        else {"name": name, "glb": base64.b64encode(glb_bytes(m, f"m{i}", name)).decode("ascii")}
        for i, (name, m) in enumerate(motions)
    ]
    spacing = 0.0
    if not overlay:  # rough body widths (a character's: 1 m)
        extents = [
            1.0 if isinstance(m, Character) else np.ptp(np.asarray(m.translations)[:, :, 0])
            for _, m in motions
        ]
        spacing = max(1.2, 1.5 * max(float(e) for e in extents))
    audio = ""
    if music is not None:
        music = Path(music)
        mime = _AUDIO_TYPES.get(music.suffix.lower())
        if mime is None:
            raise InputError(f"{music}: unsupported audio type {music.suffix!r} ({', '.join(_AUDIO_TYPES)})")
        probe_audio(music)  # audio the project's reader accepts (header checked), not any file
        sound = read_bytes(music, max_bytes=MAX_MUSIC_BYTES, what="music file to embed", error=InputError)
        audio = f'<audio id="music" preload="auto" src="{_data_uri(sound, mime)}"></audio>'
    assets = files("skeleton_mamba.tasks.motion.render.viewer")
    notes = [f"{name}: {m.scale.describe()}" for name, m in motions if getattr(m, "scale", METRES) != METRES]
    data = {"motions": entries, "metrics": listed_metrics(metrics), "notes": notes, "spacing": spacing,
            "floor": 0.0}  # fmt: skip
    fields = {
        "__TITLE__": html.escape(" vs ".join(name for name, _ in motions)),
        **three_modules(),
        "__AUDIO__": audio,
        "__DATA__": script_json(data),
    }
    template = assets.joinpath("viewer.html").read_text(encoding="utf-8")
    # one pass: a placeholder spelled inside a motion's name is not substituted again
    page = re.sub("|".join(fields), lambda match: fields[match.group()], template)
    with atomic_open(out, "w") as f:
        f.write(page)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm view``; returns 0 on success (bad input raises: `sm` prints one line)."""
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        output_file(args.out)
        motions = []
        for m in args.motions:
            character = read_character(m)  # a skinned glTF / VRM: its own meshes
            if character is not None:
                motions.append((Path(m).stem, character))
                continue
            motion = load_skeleton_motion(m, args.skeleton, args.motion_fps, args.units, args.scale)
            if motion.scale != METRES:
                print(motion.scale.line(m), file=sys.stderr)
            motions.append((Path(m).stem, motion))
        out = write_view(motions, args.out, music=args.music, metrics=args.metrics, overlay=args.overlay)
    except (ValueError, KeyError) as e:  # the readers' argument checks name the file too: one line, exit 2
        raise InputError(one_line_message(e)) from e
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB)")
    return 0
