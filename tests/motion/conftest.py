"""Fixtures of the toolkit's tests (``tests/motion/``)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion
from tests.helpers.motions import rest_pose
from tests.helpers.music import click_track

REAL_NAMES = ["gBR_sBM_cAll_d04_mBR0_ch01", "gBR_sBM_cAll_d05_mBR0_ch02", "gBR_sBM_cAll_d06_mBR0_ch03"]


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """Folders of generated (npz, 60 fps) and real (AIST++ pkl) dances named after AIST++ sequences, and a
    120 BPM click track as their music: ``(generated, real, music)``."""
    root = tmp_path_factory.mktemp("evaluate")
    rng = np.random.default_rng(0)
    gen, real, music = root / "generated", root / "real", root / "music"
    for d in (gen, real, music):
        d.mkdir()
    for i in range(3):  # generated: our npz with joints at 60 fps, named after the AIST++ sequence
        t = np.arange(700)[:, None, None]
        sway = 0.05 * np.sin(2 * np.pi * t / (40 + 5 * i)) * np.array([1.0, 0.2, 0.5])
        joints = rest_pose()[None] + sway + rng.normal(0, 0.005, (700, 24, 3))
        save_motion(gen / f"{REAL_NAMES[i]}.npz", MotionData(fps=60, joints=joints.astype(np.float32)))
    for name in REAL_NAMES:  # real: AIST++ motion pickles (SMPL parameters, 60 fps)
        poses = rng.normal(0, 0.2, (600, 72)).cumsum(0) * 0.02
        trans = np.cumsum(rng.normal(0, 0.5, (600, 3)), axis=0) + np.array([0.0, 90.0, 0.0])
        with open(real / f"{name}.pkl", "wb") as f:
            pickle.dump({"smpl_poses": poses, "smpl_trans": trans, "smpl_scaling": np.array([100.0])}, f)
    click_track(music / "mBR0.wav", bpm=120.0, seconds=12.0)
    return gen, real, music
