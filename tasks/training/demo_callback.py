"""The base of the demos' end-of-training callbacks: where they write and how they render.

Every ``*_demo.yaml`` recipe ends with a callback that, once ``fit`` is done, samples from held-out inputs,
scores and writes the result into ``<log dir>/<out_subdir>/`` (``runs/<name>/version_N/demo``).
"""

from __future__ import annotations

from pathlib import Path

from lightning.pytorch import Callback, Trainer

from skeleton_mamba.tasks.motion.render import RenderStyle

__all__ = ["DemoCallback"]


class DemoCallback(Callback):
    """Where a demo writes and the size of its renderings.

    Args:
        out_subdir: folder under the trainer's log dir (``runs/<name>/version_N``).
        render: write the renderings (a demo may take a format name instead of True).
        width: video width (multiple of 16).
        height: video height (multiple of 16).
    """

    def __init__(
        self, out_subdir: str = "demo", render: bool | str | None = True, width: int = 480, height: int = 352
    ) -> None:
        self.out_subdir = out_subdir
        self.render = render
        self.style = RenderStyle(width=width, height=height)

    def out_dir(self, trainer: Trainer) -> Path:
        """``<log dir>/<out_subdir>`` of ``trainer`` (its root dir without a logger)."""
        return Path(trainer.log_dir or trainer.default_root_dir) / self.out_subdir
