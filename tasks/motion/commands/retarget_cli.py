"""``sm retarget MOTION --rig RIG --out OUT [--map map.yaml] [--music FILE]``: any motion the toolkit reads
(:mod:`skeleton_mamba.tasks.motion.formats.motion_reader`) on a humanoid character
(:mod:`skeleton_mamba.tasks.motion.retarget.rig`: a skinned glTF / ``.glb``, a VRM, a BVH skeleton), by
:mod:`skeleton_mamba.tasks.motion.retarget.transfer`.

A glTF or VRM rig is written back whole (meshes, skins, materials, VRM extensions) with the animation added:
the character's own mesh moves; a BVH rig gives a BVH with its hierarchy and offsets. Same frame count and
frame rate as the source. ``--music`` writes the track's slice beside ``--out`` as ``sm export`` does.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from skeleton_mamba.errors import InputError, one_line_message
from skeleton_mamba.tasks.motion.commands.retarget_args import build_parser
from skeleton_mamba.tasks.motion.formats.export import write_music_slice
from skeleton_mamba.tasks.motion.formats.motion_reader import load_skeleton_motion
from skeleton_mamba.tasks.motion.formats.units import METRES
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_files, output_file
from skeleton_mamba.tasks.motion.retarget.rig import load_rig, read_map
from skeleton_mamba.tasks.motion.retarget.rig_output import retarget_onto
from skeleton_mamba.tasks.motion.retarget.transfer import bone_direction_errors

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm retarget``; returns 0 on success, 2 on a bad file or argument."""
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    out, rig_path = Path(args.out), Path(args.rig)
    try:
        rig_kind = "bvh" if rig_path.suffix.lower() == ".bvh" else "gltf"
        allowed = (".bvh",) if rig_kind == "bvh" else (".glb", ".vrm")
        if out.suffix.lower() not in allowed:
            raise InputError(
                f"{out}: the output of a {rig_path.suffix} rig must be a {' or '.join(allowed)} file"
            )
        output_file(out)
        if out.resolve() in (rig_path.resolve(), Path(args.motion).resolve()):
            raise InputError(f"{out}: --out would replace its own input; choose another name")
        if args.music is not None:
            claim_output_files([out.with_suffix(".wav")], out, overwrite=args.overwrite)
        rig = load_rig(rig_path, read_map(args.map) if args.map is not None else None)
        motion = load_skeleton_motion(args.motion, args.skeleton, args.motion_fps, args.units, args.scale)
        if motion.scale != METRES:
            print(motion.scale.line(args.motion), file=sys.stderr)
        result, joints, source_bones = retarget_onto(
            rig_path, rig, motion, out, Path(args.motion).stem, str(args.motion)
        )
        errors = bone_direction_errors(result.positions, rig.bones, joints, source_bones, result.driven)
        worst = max(errors, key=lambda b: float(errors[b].max()))
        mean = float(np.mean([e.mean() for e in errors.values()]))
        print(f"wrote {out} ({rig.how}: {len(result.driven)} bones driven, {motion.num_frames} frames at "
              f"{motion.fps:g} fps, scale {result.scale:.3f}; bone direction error mean {mean:.2f} deg, "
              f"worst {worst} {float(errors[worst].max()):.2f} deg)")  # fmt: skip
        if args.music is not None:
            wav = write_music_slice(args.music, 0.0, motion.num_frames / motion.fps, out.with_suffix(".wav"))
            print(f"wrote {wav}")
    except (ValueError, KeyError) as e:
        raise InputError(one_line_message(e)) from e
    return 0
