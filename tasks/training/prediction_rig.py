"""``sm predict --rig RIG [--map map.yaml]``: every dance ``sm predict`` writes also on the user's character.

The rig is read and its bones mapped when the command line is parsed, before the model, the data or the
checkpoint are touched (:func:`~skeleton_mamba.tasks.motion.retarget.rig_output.prepare_rig`: a bad rig or a
missing bone is refused in one line). It travels to the task's prediction writers as a trainer callback,
:class:`PredictionRig`; a writer that has just written ``<stem>.npz`` calls :meth:`PredictionRig.write` (found
with :meth:`PredictionRig.of`), which writes ``<stem>_rig.glb`` / ``.vrm`` / ``.bvh`` beside it, read back
from that file as ``sm retarget`` reads it (same frame count and frame rate).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lightning.pytorch import Trainer
from lightning.pytorch.callbacks import Callback

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.motion.retarget.rig_output import MAP_HELP, RigOutput, prepare_rig

__all__ = ["PredictionRig", "add_prediction_rig_arguments", "prediction_rig_from"]

RIG_HELP = (
    "also write every predicted motion on this character (skinned .glb, .vrm 0.x / 1.0 or .bvh), "
    "<stem>_rig.glb / .vrm / .bvh beside its .npz (sm retarget)"
)


def add_prediction_rig_arguments(parser) -> None:
    """``--rig`` and ``--map`` on ``sm predict``'s parser (a LightningArgumentParser)."""
    parser.add_argument("--rig", type=str | None, default=None, help=RIG_HELP)
    parser.add_argument("--map", type=str | None, default=None, help=MAP_HELP)


def prediction_rig_from(config) -> PredictionRig | None:
    """The parsed ``sm predict`` options' rig, read and mapped (None without ``--rig``).

    Raises:
        InputError: ``--map`` without ``--rig``; a missing, unreadable or non-humanoid rig (one line).
    """
    for option in ("rig", "map"):
        value = config.get(option)
        if value is not None and not Path(value).is_file():
            raise InputError(f"--{option} {value}: no such file")
    rig = prepare_rig(argparse.Namespace(rig=config.get("rig"), map=config.get("map")))
    return None if rig is None else PredictionRig(rig)


class PredictionRig(Callback):
    """The character of ``sm predict --rig``: writers put each dance they write on it (module docstring)."""

    def __init__(self, rig: RigOutput) -> None:
        self.rig = rig

    @staticmethod
    def of(trainer: Trainer | None) -> PredictionRig | None:
        """The trainer's :class:`PredictionRig`, None when ``sm predict`` was run without ``--rig``."""
        callbacks = [] if trainer is None else trainer.callbacks
        return next((c for c in callbacks if isinstance(c, PredictionRig)), None)

    def write(self, motion_file: str | Path, stem: str) -> Path:
        """``motion_file`` (an ``.npz`` just written) on the character, ``<stem>_rig<suffix>`` beside it."""
        motion_file = Path(motion_file)
        return self.rig.write_file(motion_file, motion_file.with_name(self.rig.file_name(stem)), stem)
