"""Beat-synchronised procedural SMPL-24 dances of a few styles. SYNTHETIC data.

With the beat phase ``phi(t) = t * bpm / 60`` (beats, the first beat at t = 0), every animated joint
angle and the root position are sums of ``cos(m * pi * phi)`` for ``m`` in {1, 2}::

    angle_j(t) = base_j + a_j * cos(pi * phi) + b_j * cos(2 * pi * phi)

Every term has zero derivative at integer ``phi``, so all joints stop on every beat: the kinematic speed
has its minima on the music beats (the "kinematic beats" of BeatAlign / MMV). ``m = 1`` swings once per
two beats (left on one beat, right on the next), ``m = 2`` bounces once per beat. Styles differ in which
joints move and how much (:data:`STYLES`); the seed scales each amplitude by a factor in [0.8, 1.2] and,
with ``swing_side="random"`` (the default), flips the side of each joint's ``m = 1`` swing at random. With
``swing_side="music"`` every swing keeps its listed side, so the music alone decides it: ``cos(pi * phi)``
is +1 on the even beats, which the synthetic music plays without snare (beats 1 and 3 of a bar,
:mod:`.music`), so a dancer hearing the bar knows which way to swing. Angles are about the SMPL joint's
local axes (y-up, +z forward, +x the body's left); the rest pose has the arms lowered by 70 degrees from the
T-pose.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.tasks.motion.body.rotations import euler_to_matrix, matrix_to_axis_angle
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion

__all__ = [
    "STYLES",
    "ROOT_HEIGHT",
    "SWING_SIDES",
    "beat_phase",
    "dance_motion",
    "phase_dance",
    "synthesize_dance",
    "write_dance",
]

SWING_SIDES = ("random", "music")
ROOT_HEIGHT = 0.93  # pelvis height (m) of the offset-table skeleton standing with straight legs

# style -> {joint: ((base_x, base_y, base_z), (a_x, a_y, a_z), (b_x, b_y, b_z))} in degrees (XYZ Euler),
# plus "root": ((sway_x, bounce_y, 0), yaw amplitude) in metres / degrees.
_ARMS_DOWN = {16: (0.0, 0.0, -70.0), 17: (0.0, 0.0, 70.0)}
STYLES: dict[str, dict] = {
    "bounce": {  # knees bend on every beat, arms swing forward and back over two beats
        "joints": {
            1: ((-10, 0, 0), (0, 0, 0), (-15, 0, 0)),
            2: ((-10, 0, 0), (0, 0, 0), (-15, 0, 0)),
            4: ((20, 0, 0), (0, 0, 0), (25, 0, 0)),
            5: ((20, 0, 0), (0, 0, 0), (25, 0, 0)),
            16: ((0, 0, 0), (0, 35, 0), (0, 0, 0)),
            17: ((0, 0, 0), (0, 35, 0), (0, 0, 0)),
            18: ((0, -60, 0), (0, -30, 0), (0, 0, 0)),
            19: ((0, 60, 0), (0, 30, 0), (0, 0, 0)),
            12: ((0, 0, 0), (0, 0, 0), (10, 0, 0)),
        },
        "root": ((0.05, 0.05, 0.0), 10.0),
    },
    "sway": {  # hips and torso sway side to side over two beats, arms swing
        "joints": {
            3: ((0, 0, 0), (0, 0, 8), (0, 0, 0)),
            6: ((0, 0, 0), (0, 0, 6), (0, 0, 0)),
            16: ((0, 0, 0), (0, 0, 25), (0, 0, 0)),
            17: ((0, 0, 0), (0, 0, 25), (0, 0, 0)),
            4: ((10, 0, 0), (0, 0, 0), (10, 0, 0)),
            5: ((10, 0, 0), (0, 0, 0), (10, 0, 0)),
            15: ((0, 0, 0), (0, 10, 0), (0, 0, 0)),
        },
        "root": ((0.08, 0.02, 0.0), 15.0),
    },
    "arms": {  # big arm waves over two beats, small bounce
        "joints": {
            16: ((0, 0, 40), (0, 0, 50), (0, 0, 0)),
            17: ((0, 0, -40), (0, 0, -50), (0, 0, 0)),
            18: ((0, -30, 0), (0, -30, 0), (0, 0, 0)),
            19: ((0, 30, 0), (0, 30, 0), (0, 0, 0)),
            4: ((10, 0, 0), (0, 0, 0), (12, 0, 0)),
            5: ((10, 0, 0), (0, 0, 0), (12, 0, 0)),
            9: ((0, 0, 0), (0, 8, 0), (0, 0, 0)),
        },
        "root": ((0.03, 0.03, 0.0), 10.0),
    },
}


def beat_phase(num_frames: int, fps: float, bpm: float) -> np.ndarray:
    """Beat phase ``t * bpm / 60`` of each frame (T,)."""
    return np.arange(num_frames) / fps * bpm / 60.0


def synthesize_dance(
    bpm: float,
    duration_s: float,
    fps: float = 30.0,
    style: str = "bounce",
    seed: int = 0,
    swing_side: str = "random",
) -> MotionData:
    """A dance whose joints all stop on every beat (module docstring), as SMPL parameters (y-up, metres).

    Raises:
        ValueError: unknown style or swing side, or non-positive tempo/duration/fps.
    """
    if style not in STYLES:
        raise ValueError(f"unknown dance style {style!r}; known: {sorted(STYLES)}")
    if swing_side not in SWING_SIDES:
        raise ValueError(f"unknown swing side {swing_side!r}; known: {', '.join(SWING_SIDES)}")
    if bpm <= 0 or duration_s <= 0 or fps <= 0:
        raise ValueError(f"bpm, duration and fps must be positive, got {bpm}, {duration_s}, {fps}")
    t_frames = int(round(duration_s * fps))
    euler, trans = phase_dance(beat_phase(t_frames, fps, bpm), style, seed, swing_side)
    return dance_motion(euler, trans, fps)


def phase_dance(
    phi: np.ndarray,
    style: str = "bounce",
    seed: int = 0,
    swing_side: str = "random",
    amplitude: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The joint angles (T, 24, 3) (XYZ Euler, degrees) and root position (T, 3) (m) of a dance on the beat
    phase ``phi`` (T,) (beats; integer on every beat). Any ``phi`` that is linear between beats keeps every
    joint's stops on the beats (the module docstring): a tempo that follows a recording's tracked beats too.
    ``amplitude`` (T,) scales every swing and bounce frame by frame (1: as listed); one whose slope is zero on
    every beat keeps the stops there.

    Raises:
        ValueError: unknown style or swing side.
    """
    if style not in STYLES:
        raise ValueError(f"unknown dance style {style!r}; known: {sorted(STYLES)}")
    if swing_side not in SWING_SIDES:
        raise ValueError(f"unknown swing side {swing_side!r}; known: {', '.join(SWING_SIDES)}")
    rng = np.random.default_rng(seed)
    spec = STYLES[style]
    gain = np.ones(len(phi)) if amplitude is None else np.asarray(amplitude, dtype=np.float64)
    c1, c2 = gain * np.cos(np.pi * phi), gain * np.cos(2 * np.pi * phi)  # zero slope at every beat
    euler = np.zeros((len(phi), 24, 3))
    for joint, base in _ARMS_DOWN.items():
        euler[:, joint] += base
    for joint, (base, a, b) in spec["joints"].items():
        side = rng.choice([-1.0, 1.0])  # drawn either way: the seed's amplitudes stay the same
        side = side if swing_side == "random" else 1.0
        scale = rng.uniform(0.8, 1.2)
        euler[:, joint] += np.asarray(base) + scale * (side * np.outer(c1, a) + np.outer(c2, b))
    (sway, bounce, _), yaw_amp = spec["root"]
    euler[:, 0, 1] += np.degrees(np.radians(yaw_amp) * rng.uniform(0.8, 1.2) * c1)
    trans = np.zeros((len(phi), 3))
    trans[:, 0] = sway * rng.uniform(0.8, 1.2) * c1
    trans[:, 1] = ROOT_HEIGHT - bounce * rng.uniform(0.8, 1.2) * (gain - c2) / 2  # lowest on the off-beat
    return euler, trans


def dance_motion(euler: np.ndarray, trans: np.ndarray, fps: float) -> MotionData:
    """Joint angles (T, 24, 3) (XYZ Euler, degrees) and root position (T, 3) -> SMPL :class:`MotionData`."""
    rotations = euler_to_matrix(torch.from_numpy(np.radians(euler)), "XYZ")
    poses = matrix_to_axis_angle(rotations).numpy()
    return MotionData(fps=fps, skeleton="smpl24", poses=poses.astype(np.float32), trans=trans, scaling=1.0)


def write_dance(
    out_dir: str | PathLike[str],
    bpm: float,
    duration_s: float,
    style: str = "bounce",
    seed: int = 0,
    fps: float = 30.0,
    swing_side: str = "random",
) -> Path:
    """Write ``synthetic_<style>_<bpm>bpm_s<seed>.npz`` (our motion format) and return its path."""
    motion = synthesize_dance(bpm, duration_s, fps, style, seed, swing_side)
    name = f"synthetic_{style}_{bpm:g}bpm_s{seed}.npz"
    return save_motion(Path(out_dir) / name, motion)
