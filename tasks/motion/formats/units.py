"""Length units of motion files: every reader returns metres, and says which scale it used.

Our ``.npz``, AIST++ ``.pkl`` (``smpl_trans / smpl_scaling``), HumanML3D features, joint ``.npy`` files, NTU
``.skeleton`` files (Kinect camera space) and glTF are in metres by their formats. A BVH file is in whatever
unit its author chose: centimetres, inches, metres, or CMU's (the CMU ASF files declare ``length 0.45``: one
unit is 1/0.45 inch, 5.644 cm, and the BVH conversions keep it). A BVH's unit is therefore detected from its
figure (:func:`detect_scale`): the unit among :data:`DETECTABLE_UNITS` that makes the rest pose's height
closest to :data:`TYPICAL_STATURE_M` (log scale) while inside :data:`PLAUSIBLE_STATURE_M`; the candidates
lie at least 2.2x apart, so one wins clearly. When none fits (a doll, a giant, a rest pose with no height),
the figure is scaled to :data:`TYPICAL_STATURE_M` and the note says so. ``--units`` or ``--scale`` on
``sm export``, ``sm view`` and ``sm render`` replace the detection (and apply to any file).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "DETECTABLE_UNITS",
    "PLAUSIBLE_STATURE_M",
    "TYPICAL_STATURE_M",
    "UNIT_METRES",
    "UnitScale",
    "add_unit_arguments",
    "choose_scale",
    "detect_scale",
]

# metres per unit of the names ``--units`` takes
UNIT_METRES: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}
CMU_UNIT_M = 0.0254 / 0.45  # the CMU motion-capture ASF files' ``:units length 0.45``: 1/0.45 inch
DETECTABLE_UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "in": 0.0254,
    "CMU units (1/0.45 in)": CMU_UNIT_M,
}
TYPICAL_STATURE_M = 1.7
PLAUSIBLE_STATURE_M = (0.8, 2.6)  # children to the tallest adults; a detected unit must land inside


@dataclass(frozen=True)
class UnitScale:
    """Metres per file unit and how it was chosen (``note``: one phrase for the console and metadata)."""

    metres_per_unit: float
    note: str

    def describe(self) -> str:
        """``lengths x S to metres (NOTE)``."""
        return f"lengths x {self.metres_per_unit:.6g} to metres ({self.note})"

    def line(self, source: str) -> str:
        """The line a command prints on stderr: ``FILE: lengths x S to metres (NOTE)``."""
        return f"{source}: {self.describe()}"


METRES = UnitScale(1.0, "metres, by the file format")


def detect_scale(height: float) -> UnitScale:
    """The unit that makes a figure ``height`` file units tall a person (module docstring).

    Args:
        height: the figure's height at rest in file units (>= 0).
    """
    if not (math.isfinite(height) and height > 0):
        return UnitScale(1.0, "the figure has no height at rest: lengths kept; pass --units or --scale")
    name, unit = min(
        DETECTABLE_UNITS.items(), key=lambda kv: abs(math.log(height * kv[1] / TYPICAL_STATURE_M))
    )
    stature = height * unit
    if PLAUSIBLE_STATURE_M[0] <= stature <= PLAUSIBLE_STATURE_M[1]:
        return UnitScale(unit, f"unit detected: {name}, a figure {stature:.2f} m tall at rest")
    scale = TYPICAL_STATURE_M / height
    return UnitScale(
        scale,
        f"unknown unit (the figure is {height:.4g} units tall): scaled to a {TYPICAL_STATURE_M} m figure; "
        "pass --units or --scale",
    )


def choose_scale(units: str | None, scale: float | None, height: float | None = None) -> UnitScale:
    """The scale a reader applies: ``--scale``, else ``--units``, else detection from ``height`` (BVH), else
    metres (the other formats).

    Raises:
        ValueError: both given, an unknown unit, or a scale that is not a positive finite number.
    """
    if units is not None and scale is not None:
        raise ValueError("give --units or --scale, not both")
    if scale is not None:
        if not (math.isfinite(scale) and 0 < scale <= 1e3):
            raise ValueError(f"--scale {scale:g}: metres per file unit must be a number in (0, 1000]")
        return UnitScale(float(scale), f"given: --scale {scale:g}")
    if units is not None:
        if units not in UNIT_METRES:
            raise ValueError(f"--units {units!r}: expected one of {', '.join(UNIT_METRES)}")
        return UnitScale(UNIT_METRES[units], f"given: --units {units}")
    if height is not None:
        return detect_scale(height)
    return METRES


def add_unit_arguments(parser) -> None:
    """``--units`` and ``--scale`` of ``sm export``, ``sm view`` and ``sm render`` (an argparse parser)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--units",
        choices=tuple(UNIT_METRES),
        default=None,
        help="length unit of the input (default: metres, except BVH, whose unit is detected from the "
        "figure's height at rest; the chosen scale is printed)",
    )
    group.add_argument("--scale", type=float, default=None, help="metres per input unit (replaces --units)")
