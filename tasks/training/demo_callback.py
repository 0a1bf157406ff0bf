"""The base of the demos' end-of-training callbacks: where they write and how they render.

Every ``*_demo.yaml`` recipe ends with a callback that, once ``fit`` is done, samples from held-out inputs,
scores and writes the result into ``<log dir>/<out_subdir>/`` (``runs/<name>/version_N/demo``).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from lightning.pytorch import Callback, Trainer

from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.tasks.motion.formats.export import write_motion
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.motion.formats.motion_reader import load_skeleton_motion
from skeleton_mamba.tasks.motion.render.skeleton import RenderStyle
from skeleton_mamba.tasks.motion.render.view import write_view

__all__ = ["DemoCallback", "write_summary"]


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

    def write_sample(
        self, out: Path, name: str, wav: Path, motions: Iterable[tuple[str, MotionData, str]]
    ) -> dict[str, Any]:
        """Write each ``(kind, motion, title)`` of the held-out sequence ``name`` as ``<stem>_<kind>`` files
        in ``out`` with the music ``wav`` (:func:`~skeleton_mamba.tasks.motion.formats.export.write_motion`;
        the stem is ``name``, prefixed ``synthetic_`` unless it starts so).

        Returns:
            The sample's record for ``demo.json``: its sequence, music and, per kind, the paths written.
        """
        stem = name if name.startswith("synthetic") else f"synthetic_{name}"
        record: dict[str, Any] = {"sequence": name, "music": str(wav)}
        for kind, motion, title in motions:
            files = write_motion(
                motion, out, f"{stem}_{kind}", music=wav, render=self.render, style=self.style, title=title
            )
            record[kind] = {k: str(v) for k, v in vars(files).items() if v is not None}
        return record


def write_summary(out: Path, summary: dict[str, Any]) -> Path | None:
    """``summary`` as ``out/demo.json``, and the viewer of its first sample's dance and reference with its
    ``scores`` (``out/view.html``, returned; ``None`` when ``summary["samples"]`` is empty)."""
    out.mkdir(parents=True, exist_ok=True)
    with atomic_open(out / "demo.json", "w", encoding="utf-8") as f:
        f.write(json.dumps(summary, indent=2))
    if not summary["samples"]:
        return None
    first = summary["samples"][0]
    motions = [(kind, load_skeleton_motion(first[kind]["npz"])) for kind in ("dance", "reference")]
    return write_view(motions, out / "view.html", first["music"], summary["scores"])
