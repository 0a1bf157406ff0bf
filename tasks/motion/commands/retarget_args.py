"""The command line of ``sm retarget`` (argparse only: ``--help`` imports no torch)."""

from __future__ import annotations

import argparse

from skeleton_mamba.tasks.motion.commands.cli_options import command_parser
from skeleton_mamba.tasks.motion.formats.units import add_unit_arguments
from skeleton_mamba.tasks.motion.io.option_types import fps_option

__all__ = ["build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "sm retarget",
        "Put a motion on your character: a skinned glTF / .glb, a VRM or a BVH skeleton.",
        "example:\n  sm retarget dance.npz --rig character.vrm --out character_dance.vrm --music song.wav",
    )
    p.add_argument(
        "motion",
        help="motion file: .npz (ours), .pkl (AIST++), .npy: (T,J,3) joints or (T,263) HumanML3D features, "
        ".bvh, .skeleton, .glb",
    )
    p.add_argument("--rig", required=True, help="the character: skinned .glb, .vrm (0.x or 1.0) or .bvh")
    p.add_argument(
        "--out",
        required=True,
        help="output file in an existing folder: .glb / .vrm for a glTF rig, .bvh for a BVH",
    )
    p.add_argument(
        "--map", default=None, help="YAML bone map `humanoid bone: rig joint` (hips, leftUpperArm, ...)"
    )
    p.add_argument("--music", default=None, help="audio file: its first seconds are written beside as .wav")
    p.add_argument("--skeleton", default=None, help="skeleton of a .npy joint file (smpl24, ntu25, ...)")
    p.add_argument(
        "--motion-fps", type=fps_option, default=None, help="input frame rate (overrides the file's)"
    )
    p.add_argument(
        "--overwrite", action="store_true", help="with --music: replace an existing .wav beside --out"
    )
    add_unit_arguments(p)
    return p
