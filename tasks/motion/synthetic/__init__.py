"""Procedural SYNTHETIC dance and music for demos without AIST++ (every file name starts with ``synthetic_``).

:mod:`.music` synthesises drums + bass at a given tempo (wav); :mod:`.dance` makes beat-synchronised
SMPL-24 dances whose joints stop on every beat. :func:`make_demo_set` writes matching pairs
``synthetic_<style>_<bpm>bpm_s<seed>.npz`` + ``.wav`` with the same stem, which ``sm make-ego`` pairs
automatically (the wav is the music of the dance). Run ``python -m skeleton_mamba.tasks.motion.synthetic
--out DIR`` to write a demo set.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np

from skeleton_mamba.tasks.motion.synthetic.dance import STYLES, synthesize_dance, write_dance
from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

__all__ = ["make_demo_set", "synthesize_dance", "synthesize_music", "write_dance", "write_music"]


def make_demo_set(
    out_dir: str | PathLike[str],
    count: int = 4,
    duration_s: float = 20.0,
    seed: int = 0,
    fps: float = 30.0,
    swing_side: str = "random",
) -> list[tuple[Path, Path]]:
    """Write ``count`` (dance ``.npz``, music ``.wav``) pairs, styles in turn, tempi in 90-140 BPM
    (``swing_side``: see :func:`synthesize_dance`).

    Returns:
        The (motion path, music path) pairs.
    """
    rng = np.random.default_rng(seed)
    styles = sorted(STYLES)
    pairs = []
    for k in range(count):
        bpm = float(rng.integers(90, 141))
        motion = write_dance(out_dir, bpm, duration_s, styles[k % len(styles)], seed + k, fps, swing_side)
        music = write_music(motion.with_suffix(".wav"), synthesize_music(bpm, duration_s, seed=seed + k))
        pairs.append((motion, music))
    return pairs
