"""``sm export MOTION --out dance.glb [--music FILE] [--skeleton J] [--motion-fps N] [--units U|--scale S]``.

Writes any motion file the toolkit reads (:mod:`skeleton_mamba.tasks.motion.formats.motion_reader`: ``.npz``,
AIST++ ``.pkl``, ``.bvh``, joints ``.npy``, HumanML3D features ``.npy`` (T, 263), NTU ``.skeleton``, ``.glb``)
as a glTF 2.0 binary (:mod:`skeleton_mamba.tasks.motion.formats.gltf`): a skinned skeleton and one animation,
in metres. A scale other than metres by the file's format (a BVH's detected unit, ``--units``, ``--scale``) is
stated on stderr; every file records it in its ``asset.extras``. ``--music`` writes the track's slice of the
motion's length beside it (``dance.wav``), as glTF has no audio; ``--rig RIG`` (``--map``) the motion on that
character too (``dance_rig.glb`` / ``.vrm`` / ``.bvh``,
:mod:`skeleton_mamba.tasks.motion.retarget.rig_output`). ``--out``'s folder must exist.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from skeleton_mamba.errors import InputError, one_line_message
from skeleton_mamba.tasks.motion.commands.export_args import build_parser
from skeleton_mamba.tasks.motion.formats.export import write_music_slice
from skeleton_mamba.tasks.motion.formats.gltf import write_glb
from skeleton_mamba.tasks.motion.formats.motion_reader import load_skeleton_motion
from skeleton_mamba.tasks.motion.formats.units import METRES
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_files, output_file
from skeleton_mamba.tasks.motion.retarget.rig_output import prepare_rig, rig_file_names

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm export``; returns 0 on success, 2 on a bad file or argument."""
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    out = Path(args.out)
    try:
        if out.suffix.lower() != ".glb":
            raise InputError(f"{out}: the output must be a .glb file")
        output_file(out)
        beside = [out.with_suffix(".wav")] if args.music is not None else []
        beside += [out.with_name(name) for name in rig_file_names([out.stem], args.rig)]
        # the .wav and the rig's file beside the .glb: not named by the user, so not replaced unasked
        claim_output_files(beside, out, overwrite=args.overwrite)
        rig = prepare_rig(args, beside[-1:] if args.rig is not None else (), inputs=[args.motion])
        motion = load_skeleton_motion(args.motion, args.skeleton, args.motion_fps, args.units, args.scale)
        if motion.scale != METRES:
            print(motion.scale.line(args.motion), file=sys.stderr)
        write_glb(motion, out, name=Path(args.motion).stem)
        print(f"wrote {out} ({len(motion.names)} joints, {motion.num_frames} frames at {motion.fps:g} fps)")
        if rig is not None:
            path = rig.write(motion, out.with_name(rig.file_name(out.stem)), Path(args.motion).stem)
            print(f"wrote {path} (on the rig {rig.path}, {rig.rig.how})")
        if args.music is not None:
            wav = write_music_slice(args.music, 0.0, motion.num_frames / motion.fps, out.with_suffix(".wav"))
            print(f"wrote {wav}")
    except (ValueError, KeyError) as e:  # the readers' argument checks name the file too: one line, exit 2
        raise InputError(one_line_message(e)) from e
    return 0
