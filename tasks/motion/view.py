"""``sm view MOTION [MOTION ...] [--music FILE] [--metrics demo.json] [--overlay] --out view.html``.

Writes ONE self-contained HTML page (opens from disk, no network): three.js r170 and its OrbitControls (the
npm package ``three``, MIT, bundled in :mod:`.viewer`) as data-URI modules, each motion as its glTF binary
(:mod:`.gltf`, base64), the music as a data-URI ``<audio>`` element. The page draws the skeletons on a ground
grid with shadows, fits an orbit camera to the whole motion, and has play / pause / scrub / speed; with music
the audio element is the clock and a scrub moves it. Several motions stand side by side (or ``--overlay``),
named and coloured, with the numeric metrics of a ``demo.json`` listed. ``window.smViewer`` exposes the
clock, ``seek(t)``, the camera and the projection of each motion's root to canvas pixels.
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

from skeleton_mamba.tasks.motion.atomic import atomic_open
from skeleton_mamba.tasks.motion.errors import InputError, one_line_message
from skeleton_mamba.tasks.motion.gltf import SkeletonMotion, load_skeleton_motion, write_glb
from skeleton_mamba.tasks.motion.option_types import fps_option

__all__ = ["write_view", "main"]

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


def _numeric_metrics(metrics: dict | None) -> dict[str, float | str]:
    """Top-level numbers (and one level of nested numbers as ``outer.inner``) of a metrics dict."""
    out: dict[str, float | str] = {}
    for key, value in (metrics or {}).items():
        if isinstance(value, bool):
            continue
        if isinstance(value, (int, float)):
            out[str(key)] = float(value)
        elif isinstance(value, dict):
            out.update({f"{key}.{k}": float(v) for k, v in value.items() if isinstance(v, (int, float))})
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
        metrics: a dict or the path of a JSON file (e.g. a demo's ``demo.json``); numbers are listed.
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
    data = {"motions": entries, "metrics": _numeric_metrics(metrics), "spacing": spacing, "floor": floor}
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
    p.add_argument("motions", nargs="+", help="motion files: .npz, .pkl, .bvh, .npy (T,J,3), .skeleton")
    p.add_argument("--out", required=True, help="output .html")
    p.add_argument("--music", default=None, help="audio file played in sync (.wav, .mp3, .ogg, .flac)")
    p.add_argument("--metrics", default=None, help="a JSON file of metrics to list (e.g. demo.json)")
    p.add_argument("--overlay", action="store_true", help="draw the motions on top of one another")
    p.add_argument("--skeleton", default=None, help="skeleton of .npy joint files (smpl24, ntu25, ...)")
    p.add_argument(
        "--motion-fps", type=fps_option, default=None, help="input frame rate (overrides the files')"
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm view``; returns 0 on success (bad input raises: `sm` prints one line)."""
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        motions = [
            (Path(m).stem, load_skeleton_motion(m, skeleton=args.skeleton, motion_fps=args.motion_fps))
            for m in args.motions
        ]
        out = write_view(motions, args.out, music=args.music, metrics=args.metrics, overlay=args.overlay)
    except (ValueError, KeyError) as e:  # the readers' argument checks name the file too: one line, exit 2
        raise InputError(one_line_message(e)) from e
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB)")
    return 0
