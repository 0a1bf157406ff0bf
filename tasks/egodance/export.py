"""Write a sampled EMM dance (motion tokens) as files: ``.npz``, BVH and an mp4 with the music muxed in.

Used by ``sm dance`` (:mod:`.dance_cli`) and the demo callback (:mod:`.demo`).
"""

from __future__ import annotations

from pathlib import Path

import torch

from skeleton_mamba.tasks.egodance.representation import FPS
from skeleton_mamba.tasks.egodance.sampling import tokens_to_motion
from skeleton_mamba.tasks.motion.formats.export import DanceFiles, write_motion
from skeleton_mamba.tasks.motion.render.skeleton import RenderStyle

__all__ = ["write_dance"]


def write_dance(
    tokens: torch.Tensor,
    out_dir: str | Path,
    name: str,
    music: str | Path | None = None,
    music_start_s: float = 0.0,
    fps: float = FPS,
    render: bool = True,
    style: RenderStyle | None = None,
    title: str | None = None,
    progress: bool = False,
) -> DanceFiles:
    """Motion tokens (T, 24, 10) -> ``<name>.npz``, ``<name>.bvh`` and ``<name>.mp4`` in ``out_dir``.

    Args:
        tokens: the sampled dance (:mod:`.representation`).
        fps: frame rate of the dance.

    The others as :func:`~skeleton_mamba.tasks.motion.formats.export.write_motion`.
    """
    return write_motion(
        tokens_to_motion(tokens, fps), out_dir, name, music, music_start_s, render, style, title, progress
    )
