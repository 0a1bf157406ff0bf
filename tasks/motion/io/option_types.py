"""Range-checked command-line values: every fps, size, count and duration option is checked where it is
parsed (argparse's ``type=``), so a negative, infinite or absurd value stops with argparse's line
``sm CMD: error: argument --opt: ...`` (exit 2) before anything uses it.

The bounds are the project's (shared with the recipes' checks in ``tasks/training/recipe_policy.py``):
frame rates :data:`FPS_RANGE` (files' too: :mod:`.value_checks`), frame counts up to :data:`MAX_FRAMES`,
images up to :data:`MAX_IMAGE_SIZE` pixels on a side, worker processes up to :data:`MAX_WORKERS`, seeds as
Lightning's. Plain Python: the commands' parsers use them before numpy or torch is imported.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = [
    "FPS_RANGE",
    "MAX_FRAMES",
    "MAX_IMAGE_SIZE",
    "MAX_SEED",
    "MAX_WORKERS",
    "file_name_option",
    "fps_option",
    "image_size_option",
    "int_option",
    "is_plain_name",
    "real_option",
    "seed_option",
]

FPS_RANGE = (1.0, 1000.0)  # frames per second of any motion, option or file
MAX_FRAMES = 1_000_000  # frames of a window, clip or sequence: 9 hours at 30 fps
MAX_IMAGE_SIZE = 4096  # pixels on a side
MAX_WORKERS = 1024  # worker processes
MAX_SEED = 2**32 - 1  # numpy's and Lightning's seed range


def int_option(low: int, high: int, what: str = "an integer") -> Callable[[str], int]:
    """An argparse ``type`` accepting integers from ``low`` to ``high``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {what} from {low:,} to {high:,}, got {text!r}"
            ) from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"expected {what} from {low:,} to {high:,}, got {value:,}")
        return value

    return parse


def real_option(
    low: float, high: float, what: str = "a number", *, low_open: bool = False, high_open: bool = False
) -> Callable[[str], float]:
    """An argparse ``type`` accepting finite numbers from ``low`` to ``high`` (``*_open``: bound excluded)."""
    span = f"{'above' if low_open else 'from'} {low:g} to {high:g}{' (excluded)' if high_open else ''}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what} {span}, got {text!r}") from None
        inside = (low < value if low_open else low <= value) and (
            value < high if high_open else value <= high
        )
        if not (math.isfinite(value) and inside):
            raise argparse.ArgumentTypeError(f"expected {what} {span}, got {text}")
        return value

    return parse


fps_option = real_option(*FPS_RANGE, "a frame rate (frames per second)")
"""``--fps`` / ``--motion-fps``: :data:`FPS_RANGE`."""

seed_option = int_option(0, MAX_SEED, "a seed")
"""``--seed``: 0 to 2^32 - 1."""


def image_size_option(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` (``640x480``), each side 1 to :data:`MAX_IMAGE_SIZE` pixels."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 640x480, got {text!r}") from None
    if not (1 <= width <= MAX_IMAGE_SIZE and 1 <= height <= MAX_IMAGE_SIZE):
        raise argparse.ArgumentTypeError(
            f"expected sides of 1 to {MAX_IMAGE_SIZE} pixels, got {width}x{height}"
        )
    return width, height


def is_plain_name(name: str) -> bool:
    """Whether ``name`` names an entry inside a folder: not empty, not ``.`` or ``..``, no folder separator
    (``/``, ``\\``) and no NUL."""
    return bool(name) and name not in (".", "..") and not any(c in name for c in ("/", "\\", "\0"))


def file_name_option(text: str) -> str:
    """An argparse ``type`` for a file name (``--name``): a plain name (:func:`is_plain_name`), so what a
    command writes stays inside its output folder."""
    if not is_plain_name(text):
        raise argparse.ArgumentTypeError(
            f"{text!r}: must be a plain file name (no '/', '\\' or '..'); choose the folder with --out"
        )
    return text
