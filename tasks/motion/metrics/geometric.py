"""The 32-d geometric ("manual") motion feature of AIST++ (FID_g, Div_g), vectorised in torch.

Port of google/aistplusplus_api ``aist_plusplus/features/manual.py`` + ``utils.py`` at the fixed version
(SMPL name-order and extraction-range fixes; Bailando's ``manual_new.py`` matches).
Boolean relational predicates (Mueller et al.'s relational features, as in fairmotion) are evaluated on
frames ``1 .. T-1`` (with frame ``t-1`` as the previous frame) and averaged over frames, so each value is
the fraction of frames on which the predicate holds. Input is y-up SMPL-24 joint positions in metres.

Predicates, all strict ``>`` (``a, b, c, d`` are joints or the pseudo-joints ``zero``, ``y_unit``,
``minus_y_unit``, ``y_min = (0, min_j y_j, 0)`` of the current frame):

* ``move(a, b, c; tau)``: velocity of ``c`` relative to ``a`` along ``unit(b - a)``, times 120, > tau;
* ``nmove(a, b, c, d; tau)``: velocity of ``d`` relative to ``a`` along ``unit((c - a) x (b - a))`` x 120;
* ``plane(a, b, c, d; tau)``: distance of ``d`` from the plane through ``a``, normal ``(c - a) x (b - a)``;
* ``nplane(a, b, c, d; tau)``: distance of ``d`` from the plane through ``c`` with normal ``b - a``;
* ``angle(a, b, c, d; lo, hi)``: angle in degrees between ``b - a`` and ``d - c`` in the open range;
* ``fast(a; tau)``: ``|p_a - p_a,prev| x 120 > tau``.

The "x 120" is the reference's ``time_per_frame = 1/120`` although AIST++ runs at 60 fps; it is kept so
values match published FID_g. Degenerate directions (zero-length vectors) give NaN and hence ``False``,
as in the reference.
"""

from __future__ import annotations

import math

import torch

from skeleton_mamba.skeletons import SMPL24

__all__ = ["GEOMETRIC_FEATURE_NAMES", "geometric_features"]

# AIST++ joint names -> our SMPL-24 names (same order, indices from skeleton_mamba.skeletons.SMPL24).
_AIST_TO_SMPL = {
    "root": "pelvis", "lhip": "left_hip", "rhip": "right_hip", "belly": "spine1", "lknee": "left_knee",
    "rknee": "right_knee", "spine": "spine2", "lankle": "left_ankle", "rankle": "right_ankle",
    "chest": "spine3", "ltoes": "left_foot", "rtoes": "right_foot", "neck": "neck",
    "linshoulder": "left_collar", "rinshoulder": "right_collar", "head": "head",
    "lshoulder": "left_shoulder", "rshoulder": "right_shoulder", "lelbow": "left_elbow",
    "relbow": "right_elbow", "lwrist": "left_wrist", "rwrist": "right_wrist", "lhand": "left_hand",
    "rhand": "right_hand",
}  # fmt: skip
_J = {aist: SMPL24.index(smpl) for aist, smpl in _AIST_TO_SMPL.items()}


def _dist(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    return math.dist(a, b)


# Body constants of the reference (fixed joint positions of the mean SMPL body).
_LSHOULDER = (1.99113488e-01, 2.36807942e-01, -1.80702247e-02)
HUMERUS_LENGTH = _dist(_LSHOULDER, (4.54445392e-01, 2.21158922e-01, -4.10167128e-02))  # hl, 0.25684
SHOULDER_WIDTH = _dist(_LSHOULDER, (-1.91692337e-01, 2.36928746e-01, -1.23055102e-02))  # sw, 0.39085
HIP_WIDTH = _dist(  # hw, 0.11925
    (5.64076714e-02, -3.23069185e-01, 1.09197125e-02), (-6.24834076e-02, -3.31302464e-01, 1.50412619e-02)
)
VELOCITY_SCALE = 120.0  # 1 / time_per_frame of the reference

hl, sw, hw = HUMERUS_LENGTH, SHOULDER_WIDTH, HIP_WIDTH
# (kind, joint arguments, threshold or angle range), in the reference's order.
_FEATURES: tuple[tuple[str, tuple[str, ...], float | tuple[float, float]], ...] = (
    ("nmove", ("neck", "rhip", "lhip", "rwrist"), 1.8 * hl),
    ("nmove", ("neck", "lhip", "rhip", "lwrist"), 1.8 * hl),
    ("nplane", ("chest", "neck", "neck", "rwrist"), 0.2 * hl),
    ("nplane", ("chest", "neck", "neck", "lwrist"), 0.2 * hl),
    ("move", ("belly", "chest", "chest", "rwrist"), 1.8 * hl),
    ("move", ("belly", "chest", "chest", "lwrist"), 1.8 * hl),
    ("angle", ("relbow", "rshoulder", "relbow", "rwrist"), (0.0, 110.0)),
    ("angle", ("lelbow", "lshoulder", "lelbow", "lwrist"), (0.0, 110.0)),
    ("nplane", ("lshoulder", "rshoulder", "lwrist", "rwrist"), 2.5 * sw),
    ("move", ("lwrist", "rwrist", "rwrist", "lwrist"), 1.4 * hl),
    ("move", ("rwrist", "root", "lwrist", "root"), 1.4 * hl),
    ("move", ("lwrist", "root", "rwrist", "root"), 1.4 * hl),
    ("fast", ("rwrist",), 2.5 * hl),
    ("fast", ("lwrist",), 2.5 * hl),
    ("plane", ("root", "lhip", "ltoes", "rankle"), 0.38 * hl),
    ("plane", ("root", "rhip", "rtoes", "lankle"), 0.38 * hl),
    ("nplane", ("zero", "y_unit", "y_min", "rankle"), 1.2 * hl),
    ("nplane", ("zero", "y_unit", "y_min", "lankle"), 1.2 * hl),
    ("nplane", ("lhip", "rhip", "lankle", "rankle"), 2.1 * hw),
    ("angle", ("rknee", "rhip", "rknee", "rankle"), (0.0, 110.0)),
    ("angle", ("lknee", "lhip", "lknee", "lankle"), (0.0, 110.0)),
    ("fast", ("rankle",), 2.5 * hl),
    ("fast", ("lankle",), 2.5 * hl),
    ("angle", ("neck", "root", "rshoulder", "relbow"), (25.0, 180.0)),
    ("angle", ("neck", "root", "lshoulder", "lelbow"), (25.0, 180.0)),
    ("angle", ("neck", "root", "rhip", "rknee"), (50.0, 180.0)),
    ("angle", ("neck", "root", "lhip", "lknee"), (50.0, 180.0)),
    ("plane", ("rankle", "neck", "lankle", "root"), 0.5 * hl),
    ("angle", ("neck", "root", "zero", "y_unit"), (70.0, 110.0)),
    ("nplane", ("zero", "minus_y_unit", "y_min", "rwrist"), -1.2 * hl),
    ("nplane", ("zero", "minus_y_unit", "y_min", "lwrist"), -1.2 * hl),
    ("fast", ("root",), 2.3 * hl),
)
del hl, sw, hw
GEOMETRIC_FEATURE_NAMES = tuple(f"{kind}({', '.join(args)})" for kind, args, _ in _FEATURES)


def _dot_unit(v: torch.Tensor, direction: torch.Tensor) -> torch.Tensor:
    """``v . direction / |direction|`` over the last axis (NaN for a zero direction)."""
    return (v * direction).sum(-1) / direction.norm(dim=-1)


def geometric_features(positions: torch.Tensor) -> torch.Tensor:
    """Geometric (manual) features of y-up SMPL-24 joint-position sequences.

    Args:
        positions: ``(..., T, 24, 3)`` joint positions in metres (y-up), ``T >= 2``.

    Returns:
        ``(..., 32)`` float64 fractions of frames ``1 .. T-1`` on which each predicate holds
        (names in :data:`GEOMETRIC_FEATURE_NAMES`).

    Examples:
        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> geometric_features(torch.randn(2, 10, 24, 3)).shape
        torch.Size([2, 32])
    """
    if positions.ndim < 3 or positions.shape[-2:] != (24, 3):
        raise ValueError(f"positions must be (..., T, 24, 3) SMPL-24 joints, got {tuple(positions.shape)}")
    if positions.shape[-3] < 2:
        raise ValueError(f"geometric features need at least 2 frames, got {positions.shape[-3]}")
    p = positions.to(torch.float64)
    cur, prev = p[..., 1:, :, :], p[..., :-1, :, :]
    ones = torch.ones_like(cur[..., 0, 0])
    zeros = torch.zeros_like(ones)
    pseudo = {
        "zero": torch.stack([zeros, zeros, zeros], -1),
        "y_unit": torch.stack([zeros, ones, zeros], -1),
        "minus_y_unit": torch.stack([zeros, -ones, zeros], -1),
        "y_min": torch.stack([zeros, cur[..., 1].amin(-1), zeros], -1),
    }

    def now(name: str) -> torch.Tensor:
        return pseudo[name] if name in pseudo else cur[..., _J[name], :]

    def before(name: str) -> torch.Tensor:
        return prev[..., _J[name], :]

    values = []
    for kind, args, thr in _FEATURES:
        if kind == "move":
            a, b, c, _ = args
            vel = (now(c) - now(a)) - (before(c) - before(a))
            value = _dot_unit(vel, now(b) - now(a)) * VELOCITY_SCALE > thr
        elif kind == "nmove":
            a, b, c, d = args
            vel = (now(d) - now(a)) - (before(d) - before(a))
            normal = torch.linalg.cross(now(c) - now(a), now(b) - now(a))
            value = _dot_unit(vel, normal) * VELOCITY_SCALE > thr
        elif kind == "plane":
            a, b, c, d = args
            normal = torch.linalg.cross(now(c) - now(a), now(b) - now(a))
            value = _dot_unit(now(d) - now(a), normal) > thr
        elif kind == "nplane":
            a, b, c, d = args
            value = _dot_unit(now(d) - now(c), now(b) - now(a)) > thr
        elif kind == "angle":
            a, b, c, d = args
            j, k = now(b) - now(a), now(d) - now(c)
            cosine = (j * k).sum(-1) / (j.norm(dim=-1) * k.norm(dim=-1))
            angle = torch.rad2deg(torch.arccos(cosine))
            value = (angle > thr[0]) & (angle < thr[1])
        else:  # fast
            (a,) = args
            value = (now(a) - before(a)).norm(dim=-1) * VELOCITY_SCALE > thr
        values.append(value)
    return torch.stack(values, dim=-1).to(torch.float64).mean(dim=-2)
