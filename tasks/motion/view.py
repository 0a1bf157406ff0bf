"""``sm view MOTION [MOTION ...] [--music FILE] [--metrics demo.json] [--overlay] [--units U|--scale S]
--out view.html``.

Writes ONE self-contained HTML page (opens from disk, no network): three.js r170 and its OrbitControls (the
npm package ``three``, MIT, bundled in :mod:`.viewer`) as data-URI modules, each motion as its glTF binary
(:mod:`.gltf`, base64), the music as a data-URI ``<audio>`` element. The page draws the skeletons on a ground
grid with shadows, fits an orbit camera to the whole motion, and has play / pause / scrub / speed; with music
the audio element is the clock and a scrub moves it. Several motions stand side by side (or ``--overlay``),
named and coloured, with the metrics of a ``demo.json`` listed by their full names (nested objects as
``scores.dance.mpjpe_m``, whole numbers as such, booleans as yes / no, short texts as they are) and the scale
each file was read with when it is not metres by its format (:mod:`.units`). Motions are read by
:mod:`.motion_reader` (our ``.glb`` exports too). ``window.smViewer`` exposes the clock, ``seek(t)``, the
camera, the projection of a world point to canvas pixels, each motion's root and joints in world space.
"""

from __future__ import annotations

import argparse
import base64
import json
import sys
from collections.abc import Sequence
from importlib.resources import files
from os import PathLike
from pathlib import Path

import numpy as np

from skeleton_mamba.tasks.motion.atomic import atomic_open, output_file
from skeleton_mamba.tasks.motion.errors import InputError, one_line_message
from skeleton_mamba.tasks.motion.gltf import SkeletonMotion, write_glb
from skeleton_mamba.tasks.motion.motion_reader import load_skeleton_motion
from skeleton_mamba.tasks.motion.units import METRES, add_unit_arguments

__all__ = ["MAX_TEXT", "listed_metrics", "write_view", "main"]

_AUDIO_TYPES = {
    ".wav": "audio/wav",
    ".mp3": "audio/mpeg",
    ".ogg": "audio/ogg",
    ".opus": "audio/ogg",
    ".flac": "audio/flac",
}


def _data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def _glb_bytes(motion: SkeletonMotion, name: str, folder: Path) -> bytes:
    path = write_glb(motion, folder / f".{name}.view.glb", name=name)
    try:
        return path.read_bytes()
    finally:
        path.unlink()


MAX_TEXT = 60  # longer texts of a metrics file (paths, descriptions) are not listed


def listed_metrics(metrics: dict | None, prefix: str = "") -> dict[str, float | int | str]:
    """The entries of a metrics dict the page lists, by full dotted name: numbers (whole numbers as ints),
    booleans as ``yes`` / ``no``, texts of at most :data:`MAX_TEXT` characters; nested dicts at any depth
    (``scores.dance.mpjpe_m``); lists and longer texts are left out."""
    out: dict[str, float | int | str] = {}
    for key, value in (metrics or {}).items():
        name = f"{prefix}{key}"
        if isinstance(value, bool):
            out[name] = "yes" if value else "no"
        elif isinstance(value, int):
            out[name] = value
        elif isinstance(value, float):
            out[name] = value if np.isfinite(value) else str(value)
        elif isinstance(value, str) and len(value) <= MAX_TEXT:
            out[name] = value
        elif isinstance(value, dict):
            out.update(listed_metrics(value, f"{name}."))
    return out


def write_view(
    motions: Sequence[tuple[str, SkeletonMotion]],
    out: str | PathLike[str],
    music: str | PathLike[str] | None = None,
    metrics: dict | str | PathLike[str] | None = None,
    overlay: bool = False,
) -> Path:
    """Write the viewer page for named motions (module docstring), atomically; returns its path.

    Args:
        motions: (name, motion) pairs, drawn left to right (all at the origin with ``overlay``).
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
        try:
            metrics = json.loads(path.read_text())
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: not a JSON file ({e.msg} at line {e.lineno})") from None
        if not isinstance(metrics, dict):
            raise ValueError(f"{path}: expected a JSON object of metrics")
    out.parent.mkdir(parents=True, exist_ok=True)
    spacing = 0.0
    if not overlay:
        extents = [np.ptp(np.asarray(m.translations)[:, :, 0]) for _, m in motions]  # rough body width
        spacing = max(1.2, 1.5 * max(float(e) for e in extents))
    floor = 0.0
    entries = [
        {"name": name, "glb": base64.b64encode(_glb_bytes(m, f"m{i}", out.parent)).decode("ascii")}
        for i, (name, m) in enumerate(motions)
    ]
    audio = ""
    if music is not None:
        music = Path(music)
        if not music.is_file():
            raise FileNotFoundError(f"{music}: no such music file")
        mime = _AUDIO_TYPES.get(music.suffix.lower())
        if mime is None:
            raise ValueError(f"{music}: unsupported audio type {music.suffix!r} ({', '.join(_AUDIO_TYPES)})")
        audio = f'<audio id="music" preload="auto" src="{_data_uri(music.read_bytes(), mime)}"></audio>'
    assets = files("skeleton_mamba.tasks.motion.viewer")
    notes = [f"{name}: {m.scale.describe()}" for name, m in motions if m.scale != METRES]
    data = {"motions": entries, "metrics": listed_metrics(metrics), "notes": notes, "spacing": spacing,
            "floor": floor}  # fmt: skip
    page = (
        assets.joinpath("viewer.html")
        .read_text(encoding="utf-8")
        .replace("__TITLE__", " vs ".join(name for name, _ in motions).replace("<", "&lt;"))
        .replace(
            "__THREE__", _data_uri(assets.joinpath("three.module.min.js").read_bytes(), "text/javascript")
        )
        .replace("__ORBIT__", _data_uri(assets.joinpath("OrbitControls.js").read_bytes(), "text/javascript"))
        .replace("__AUDIO__", audio)
        .replace("__DATA__", json.dumps(data).replace("</", "<\\/"))
    )
    with atomic_open(out, "w") as f:
        f.write(page)
    return out


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sm view", description="Write a self-contained HTML viewer of motions.")
    p.add_argument(
        "motions", nargs="+", help="motion files: .npz, .pkl, .bvh, .npy (T,J,3) or (T,263), .skeleton, .glb"
    )
    p.add_argument("--out", required=True, help="output .html, in an existing folder")
    p.add_argument("--music", default=None, help="audio file played in sync (.wav, .mp3, .ogg, .flac)")
    p.add_argument("--metrics", default=None, help="a JSON file of metrics to list (e.g. demo.json)")
    p.add_argument("--overlay", action="store_true", help="draw the motions on top of one another")
    p.add_argument("--skeleton", default=None, help="skeleton of .npy joint files (smpl24, ntu25, ...)")
    p.add_argument("--motion-fps", type=float, default=None, help="input frame rate (overrides the files')")
    add_unit_arguments(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm view``; returns 0 on success (bad input raises: `sm` prints one line)."""
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        output_file(args.out)
        motions = []
        for m in args.motions:
            motion = load_skeleton_motion(m, args.skeleton, args.motion_fps, args.units, args.scale)
            if motion.scale != METRES:
                print(motion.scale.line(m), file=sys.stderr)
            motions.append((Path(m).stem, motion))
        out = write_view(motions, args.out, music=args.music, metrics=args.metrics, overlay=args.overlay)
    except (ValueError, KeyError) as e:  # the readers' argument checks name the file too: one line, exit 2
        raise InputError(one_line_message(e)) from e
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB)")
    return 0
