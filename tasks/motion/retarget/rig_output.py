"""``--rig RIG [--map map.yaml]`` of the commands that write motions (``sm dance``, ``sm stream``,
``sm generate``, ``sm export``; ``sm predict`` through :mod:`~skeleton_mamba.tasks.training.prediction_rig`):
the motion also written on a humanoid character, ``<stem>_rig<suffix>`` (the rig's suffix: ``.glb``, ``.vrm``
or ``.bvh``) beside the command's own files, as ``sm retarget`` writes it (:mod:`.transfer`).

:func:`prepare_rig` reads the rig and maps its bones (and those of the skeleton the command writes, when
known) after the command's arguments and output claim, before any heavy work (checkpoint, music, video): a
bad rig or a missing bone is refused in one line, exit 2. :meth:`RigOutput.write_file` retargets the motion
file the command has just written, read back as ``sm retarget`` reads it, so the rig's animation has that
file's frame count and frame rate.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING

from skeleton_mamba.errors import InputError, one_line_message

if TYPE_CHECKING:  # the command lines import this module for their options: numpy and glTF only when used
    from skeleton_mamba.tasks.motion.retarget.rig import Rig

__all__ = [
    "MAP_HELP",
    "RIG_HELP",
    "RigOutput",
    "add_rig_arguments",
    "prepare_rig",
    "retarget_onto",
    "rig_file_name",
    "rig_file_names",
]


RIG_HELP = (
    "also write the motion on this character (skinned .glb, .vrm 0.x / 1.0 or .bvh) beside the other files, "
    "as <stem>_rig.glb / .vrm / .bvh (sm retarget)"
)
MAP_HELP = "with --rig: YAML bone map `humanoid bone: rig joint` (hips, ...)"


def add_rig_arguments(p, rig_help: str = RIG_HELP) -> None:
    """``--rig`` and ``--map`` on a :func:`~skeleton_mamba.tasks.motion.commands.cli_options.command_parser`
    (a missing file refused at parse)."""
    p.input_path(p.add_argument("--rig", default=None, help=rig_help))
    p.input_path(p.add_argument("--map", default=None, help=MAP_HELP))


def rig_file_name(stem: str, rig: str | PathLike[str]) -> str:
    """The file name of the motion ``stem`` on ``rig``: ``<stem>_rig<the rig's suffix>``."""
    return f"{stem}_rig{Path(rig).suffix.lower()}"


def rig_file_names(stems: Iterable[str], rig: str | PathLike[str] | None) -> list[str]:
    """:func:`rig_file_name` of each stem, none without ``--rig`` (for the command's output claim)."""
    return [] if rig is None else [rig_file_name(stem, rig) for stem in stems]


def retarget_onto(
    rig_path: str | PathLike[str], rig: Rig, motion, out: str | PathLike[str], name: str, source: str = ""
):
    """``motion`` (a :class:`~skeleton_mamba.tasks.motion.formats.gltf.SkeletonMotion` in metres,
    :func:`~skeleton_mamba.tasks.motion.formats.motion_reader.load_skeleton_motion`) retargeted onto ``rig``
    (read from ``rig_path``) and written at ``out``: the glTF / VRM with the animation ``name`` added, or a
    BVH with the rig's hierarchy. ``source``: the motion a refusal names (default ``name``). Returns
    ``(result, joints, source_bones)``: the :class:`~.transfer.Retarget`, the source's joints (T, J, 3) and
    its humanoid bones."""
    from skeleton_mamba.tasks.motion.retarget.rig import (  # lazy: with --rig only
        find_bones,
        separate_torso,
    )
    from skeleton_mamba.tasks.motion.retarget.transfer import (  # lazy: with --rig only
        retarget,
        write_bvh_rig,
        write_gltf_rig,
    )

    joints = motion.joint_positions()
    source_bones, _ = find_bones(motion.names, source or name, what="motion")
    source_bones = separate_torso(source_bones, motion.parents, joints)
    result = retarget(rig, joints, source_bones)
    if rig.kind == "bvh":
        write_bvh_rig(rig, result, motion.fps, out)
    else:
        write_gltf_rig(rig_path, rig, result, motion.fps, out, name)
    return result, joints, source_bones


@dataclass
class RigOutput:
    """A rig read and mapped for ``--rig``: ``path`` (the file), ``rig`` (:class:`~.rig.Rig`)."""

    path: Path
    rig: Rig

    def file_name(self, stem: str) -> str:
        return rig_file_name(stem, self.path)

    def write(self, motion, out: str | PathLike[str], name: str) -> Path:
        """``motion`` (a :class:`~skeleton_mamba.tasks.motion.formats.gltf.SkeletonMotion` in metres) on the
        rig, written at ``out``."""
        try:
            retarget_onto(self.path, self.rig, motion, out, name)
        except (ValueError, KeyError) as e:
            raise InputError(one_line_message(e)) from e
        return Path(out)

    def write_file(
        self, motion_file: str | PathLike[str], out: str | PathLike[str], name: str,
        skeleton: str | None = None, fps: float | None = None,
    ) -> Path:  # fmt: skip
        """The motion file a command has just written (``skeleton``, ``fps``: of a ``.npy`` of joints) on the
        rig, written at ``out``: same frame count and frame rate."""
        from skeleton_mamba.tasks.motion.formats.motion_reader import (  # lazy: with --rig only
            load_skeleton_motion,
        )

        return self.write(load_skeleton_motion(motion_file, skeleton, fps), out, name)


def prepare_rig(
    args: argparse.Namespace,
    outputs: Iterable[str | PathLike[str]] = (),
    source: list[str] | None = None,
    inputs: Iterable[str | PathLike[str]] = (),
) -> RigOutput | None:
    """``args.rig`` read and its bones mapped (``args.map``: the bone map), or None without ``--rig``.

    Args:
        outputs: the rig files the command will write: none may be the rig, the map or one of ``inputs``.
        source: the joint names of the motions the command writes, when known: their bones are mapped too.

    Raises:
        InputError: ``--map`` without ``--rig``; an output that would replace the rig or the map; the rig
            not a rig, or lacking a humanoid bone (one line naming the file).
    """
    rig_path, map_path = getattr(args, "rig", None), getattr(args, "map", None)
    if rig_path is None:
        if map_path is not None:
            raise InputError("--map: a bone map of --rig; pass --rig too")
        return None
    from skeleton_mamba.tasks.motion.retarget.rig import (  # lazy: with --rig only
        find_bones,
        load_rig,
        read_map,
    )

    rig_path = Path(rig_path)
    given = [rig_path, *inputs, *((map_path,) if map_path is not None else ())]
    resolved = {Path(p).resolve() for p in given}
    for out in outputs:
        if Path(out).resolve() in resolved:
            raise InputError(f"{out}: the motion on the rig would replace an input file; choose another name")
    try:
        rig = load_rig(rig_path, read_map(map_path) if map_path is not None else None)
        if source is not None:
            find_bones(list(source), "the motion", what="motion")
    except (ValueError, KeyError) as e:
        raise InputError(one_line_message(e)) from e
    return RigOutput(rig_path, rig)
