"""``sm convert FEATURES.npy --out JOINTS.npy [--normalized --stats DIR]``.

Turns HumanML3D 263-d features (T, 263) into joint positions (T, 22, 3) with
:func:`~skeleton_mamba.tasks.motion.formats.humanml3d_features.recover_from_ric`. Features written by the
dataset (``new_joint_vecs``) are de-normalised already; ``--normalized`` first maps ``x * Std + Mean`` with
``DIR/Mean.npy`` and ``DIR/Std.npy``. The result renders with ``sm render JOINTS.npy --out clip.mp4`` (22
joints are read as the HumanML3D skeleton at 20 fps).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from os import PathLike
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.errors import InputError, one_line_message
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.tasks.motion.formats.humanml3d_features import (
    denormalize,
    read_features,
    read_statistics,
    recover_from_ric,
)
from skeleton_mamba.tasks.motion.io.value_checks import check_finite
from skeleton_mamba.tasks.text2motion.convert_args import build_parser

__all__ = ["convert_file", "main"]


def convert_file(
    features: str | PathLike[str], out: str | PathLike[str], stats: str | PathLike[str] | None = None
) -> Path:
    """Read (T, 263) features, de-normalise with ``stats`` (folder of Mean/Std) if given, save (T, 22, 3)."""
    array = read_features(features)
    x = torch.from_numpy(array.astype(np.float64))
    if stats is not None:
        mean, std = read_statistics(stats)
        x = denormalize(x, torch.from_numpy(mean).double(), torch.from_numpy(std).double())
    with np.errstate(over="ignore"):
        joints = recover_from_ric(x).numpy().astype(np.float32)
    check_finite(joints, f"{features} (converted)", "joints", ("frame", "joint"))  # e.g. Std * x overflowed
    out = Path(out)
    if out.suffix != ".npy":
        raise ValueError(f"{out}: the output must be a .npy file")
    with atomic_open(out, "wb") as f:
        np.save(f, joints)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm convert``; returns 0 on success (bad input raises: `sm` prints one line)."""
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    if args.normalized and args.stats is None:
        raise InputError("--normalized needs --stats DIR (Mean.npy, Std.npy)")
    try:
        out = convert_file(args.features, args.out, stats=args.stats if args.normalized else None)
    except ValueError as e:  # the feature checks name the file: one line, exit 2
        raise InputError(one_line_message(e)) from e
    print(f"wrote {out}")
    return 0
