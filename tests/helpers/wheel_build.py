"""Building the wheel, and the libraries a light import must not load."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HEAVY = [
    "lightning",
    "pytorch_lightning",
    "torchmetrics",
    "transformers",
    "librosa",
    "trimesh",
    "kornia",
    "jsonargparse",
    "scipy",
    "matplotlib",
    "cv2",
    "skeleton_mamba.tasks",
]


def build_wheel(source: Path, wheel_dir: Path) -> tuple[Path, str]:
    """The wheel of the project in ``source`` (no dependencies, no build isolation) and pip's output."""
    pip_wheel = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation"]
    result = subprocess.run([*pip_wheel, "-w", str(wheel_dir), str(source)], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    (wheel,) = wheel_dir.glob("skeleton_mamba-*.whl")
    return wheel, result.stdout + result.stderr
