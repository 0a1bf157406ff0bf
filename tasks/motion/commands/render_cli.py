"""``sm render MOTION [--music FILE] --out clip.mp4|clip.gif [--fps N] [--skeleton J] [--units U|--scale S]``.

Reads any motion file the toolkit knows (:mod:`skeleton_mamba.tasks.motion.formats.motion_reader`: ``.npz``,
AIST++ ``.pkl``, joints or HumanML3D features ``.npy``, ``.bvh``, NTU ``.skeleton``, ``.glb``) in metres and
renders a skeleton animation (see :mod:`skeleton_mamba.tasks.motion.render.skeleton`); a character (a skinned
``.glb`` / ``.vrm``, ``sm retarget``'s output) is rendered with its own mesh
(:mod:`skeleton_mamba.tasks.motion.render.mesh`). The output frame rate is ``--fps``, else the motion's own up
to :data:`~.render_args.PREVIEW_FPS` (a 120 fps BVH is rendered at 30 fps: four times fewer frames, the same
motion); frames are resampled linearly and the line on stderr says so. A scale other than metres by the file's
format (a BVH's detected unit, ``--units``, ``--scale``: :mod:`skeleton_mamba.tasks.motion.formats.units`) is
stated on stderr too. ``--out``'s folder must exist.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from os import PathLike
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.errors import InputError, one_line_message
from skeleton_mamba.tasks.motion.body.resample import resample_linear
from skeleton_mamba.tasks.motion.commands.render_args import PREVIEW_FPS, build_parser
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints
from skeleton_mamba.tasks.motion.formats.units import METRES
from skeleton_mamba.tasks.motion.io.output_folder import output_file
from skeleton_mamba.tasks.motion.io.value_checks import check_fps
from skeleton_mamba.tasks.motion.render.character import is_character
from skeleton_mamba.tasks.motion.render.character_mesh import read_character_mesh
from skeleton_mamba.tasks.motion.render.mesh import render_character
from skeleton_mamba.tasks.motion.render.skeleton import render_motion

__all__ = ["PREVIEW_FPS", "render_file", "main"]


def render_file(
    motion: str | PathLike[str],
    out: str | PathLike[str],
    music: str | PathLike[str] | None = None,
    fps: float | None = None,
    skeleton: str | None = None,
    motion_fps: float | None = None,
    title: str | None = None,
    progress: bool = True,
    units: str | None = None,
    scale: float | None = None,
) -> Path:
    """Load ``motion`` (any supported file) in metres, resample it to ``fps`` (default: its own rate, at most
    :data:`~.render_args.PREVIEW_FPS`) and render it to ``out``; states the scale and any resampling on
    stderr."""

    out = output_file(out)
    if is_character(motion):  # a skinned .glb / .vrm: its own mesh
        return _render_character(motion, out, music, fps, title, progress)
    clip = load_joints(motion, skeleton=skeleton, motion_fps=motion_fps, units=units, scale=scale)
    if clip.scale != METRES:
        print(clip.scale.line(str(motion)), file=sys.stderr)
    joints, out_fps = clip.joints, check_fps(clip.fps, f"{motion}: motion frame rate")
    if fps is not None:
        check_fps(fps, "--fps")
    elif clip.fps > PREVIEW_FPS:
        fps = PREVIEW_FPS
        print(f"{motion}: {clip.fps:g} fps rendered at {fps:g} fps (frames resampled; --fps N to change)",
              file=sys.stderr)  # fmt: skip
    if fps is not None and abs(fps - clip.fps) > 1e-9:
        joints = resample_linear(torch.from_numpy(np.asarray(joints, np.float64)), clip.fps, fps).numpy()
        out_fps = fps
    return render_motion(
        joints, clip.parents, out, out_fps, music=music, names=clip.names, title=title, progress=progress
    )


def _render_character(
    path: str | PathLike[str], out: Path, music, fps: float | None, title: str | None, progress: bool
) -> Path:
    """A character file's mesh (:mod:`skeleton_mamba.tasks.motion.render.mesh`), at ``fps`` (default: the
    animation's, at most :data:`~.render_args.PREVIEW_FPS`; other rates take the nearest frame)."""
    mesh = read_character_mesh(path)
    if fps is not None:
        check_fps(fps, "--fps")
    elif mesh.fps > PREVIEW_FPS:
        fps = PREVIEW_FPS
    if fps is not None and abs(fps - mesh.fps) > 1e-9:
        count = max(1, int(np.floor((mesh.num_frames - 1) * fps / mesh.fps)) + 1)
        index = np.minimum(np.round(np.arange(count) * mesh.fps / fps).astype(int), mesh.num_frames - 1)
        print(f"{path}: {mesh.fps:g} fps rendered at {fps:g} fps (nearest frames)", file=sys.stderr)
        mesh.world, mesh.fps = mesh.world[index], float(fps)
    return render_character(mesh, out, music=music, title=title, progress=progress)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm render``; returns 0 on success (bad input raises: `sm` prints one line)."""
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    start = time.perf_counter()
    try:
        out = render_file(
            args.motion,
            args.out,
            music=args.music,
            fps=args.fps,
            skeleton=args.skeleton,
            motion_fps=args.motion_fps,
            title=args.title if args.title is not None else Path(args.motion).name,
            progress=args.progress,
            units=args.units,
            scale=args.scale,
        )
    except (ValueError, KeyError) as e:  # the readers' argument checks name the file too: one line, exit 2
        raise InputError(one_line_message(e)) from e
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0
