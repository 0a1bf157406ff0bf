"""Procedural SMPL-24 everyday actions: walk, turn, jump, squat, kick, wave, run in place. SYNTHETIC data.

The actions people type into a text-to-motion model, made as the dances of :mod:`.dance` are: joint angles
(degrees, XYZ Euler about the SMPL joint's local axes: y-up, +z forward, +x the body's left; the rest pose has
the arms lowered by 70 degrees) and the root's path as smooth functions of time, each drawn with the seed's
tempo, size, side and heading. What each action does, so a reader can tell it from the joints
(:func:`skeleton_mamba.tasks.text2motion.actions.read_action`):

- ``walk``: strides (hips and knees alternating, arms swinging) while the pelvis travels 1.0-1.4 m/s along a
  path that bends by up to 40 degrees from the first heading;
- ``turn``: steps in place while the body turns 90-180 degrees to one side;
- ``jump``: two jumps: a crouch, then the pelvis lifted 0.25-0.35 m above standing, arms thrown up;
- ``squat``: down until the thighs are level (pelvis 0.40-0.48 m lower), a hold, and up;
- ``kick``: one leg swings forward and up (the ankle 0.45 m and more above the floor), two or three times;
- ``wave``: one hand raised above the head, the forearm waving side to side;
- ``run_in_place``: knees high and fast (2.2-2.8 steps a second), arms pumping, no travel.
"""

from __future__ import annotations

import numpy as np
import torch

from skeleton_mamba.tasks.motion.body.rotations import euler_to_matrix, matrix_to_axis_angle
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.motion.synthetic.dance import ROOT_HEIGHT

__all__ = ["ACTIONS", "synthesize_action"]

ACTIONS = ("walk", "turn", "jump", "squat", "kick", "wave", "run_in_place")
_L_HIP, _R_HIP, _SPINE, _L_KNEE, _R_KNEE = 1, 2, 3, 4, 5
_L_SHOULDER, _R_SHOULDER, _L_ELBOW, _R_ELBOW = 16, 17, 18, 19


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _strides(
    euler: np.ndarray, phase: np.ndarray, hip: float, knee: float, arm: float, in_place: bool = False
) -> None:
    """Alternating legs (hip flexion is -x, knee bend +x) and the arms swinging against them; ``in_place``:
    each thigh only lifted forward (running on the spot), not also swung back."""
    s = np.sin(phase)
    back = 0.0 if in_place else 1.0
    euler[:, _L_HIP, 0] += -hip * np.maximum(s, -back)
    euler[:, _R_HIP, 0] += hip * np.minimum(s, back)
    euler[:, _L_KNEE, 0] += knee * np.maximum(0.0, -np.cos(phase + 0.6))
    euler[:, _R_KNEE, 0] += knee * np.maximum(0.0, np.cos(phase + 0.6))
    euler[:, _L_SHOULDER, 1] += arm * s
    euler[:, _R_SHOULDER, 1] += arm * s


def synthesize_action(action: str, duration_s: float, fps: float = 20.0, seed: int = 0) -> MotionData:
    """One ``action`` of ``duration_s`` seconds (module docstring), SMPL parameters, y-up, metres.

    Raises:
        ValueError: an unknown action, or a non-positive duration or frame rate.
    """
    if action not in ACTIONS:
        raise ValueError(f"unknown action {action!r}; known: {', '.join(ACTIONS)}")
    if duration_s <= 0 or fps <= 0:
        raise ValueError(f"duration and fps must be positive, got {duration_s}, {fps}")
    rng = np.random.default_rng(seed)
    frames = max(2, int(round(duration_s * fps)))
    t = np.arange(frames) / fps
    u = t / max(t[-1], 1e-9)  # 0 -> 1 over the clip
    euler = np.zeros((frames, 24, 3))
    euler[:, _L_SHOULDER, 2] = -70.0
    euler[:, _R_SHOULDER, 2] = 70.0
    heading = np.full(frames, rng.uniform(-180.0, 180.0))
    trans = np.zeros((frames, 3))
    trans[:, 1] = ROOT_HEIGHT
    side = rng.choice([-1.0, 1.0])
    if action in ("walk", "turn", "run_in_place"):
        rate = rng.uniform(*{"walk": (0.85, 1.0), "turn": (0.8, 1.0), "run_in_place": (1.1, 1.4)}[action])
        phase = 2 * np.pi * rate * t + rng.uniform(0, 2 * np.pi)
        size = {"walk": (25, 35, 25), "turn": (12, 20, 10), "run_in_place": (75, 100, 45)}[action]
        _strides(euler, phase, *size, in_place=action == "run_in_place")
        trans[:, 1] -= 0.02 * (1 - np.cos(2 * phase)) / 2
        if action == "walk":
            bend = rng.uniform(-40.0, 40.0)
            heading = heading + bend * _smoothstep(u)
            speed = rng.uniform(1.0, 1.4)
            yaw = np.radians(heading)
            step = np.stack([np.sin(yaw), np.zeros(frames), np.cos(yaw)], 1) * speed / fps
            trans[1:, [0, 2]] = np.cumsum(step[:-1], 0)[:, [0, 2]]
        elif action == "turn":
            heading = heading + side * rng.uniform(90.0, 180.0) * _smoothstep((u - 0.1) / 0.8)
        else:  # run in place: elbows bent, knees high
            euler[:, _L_ELBOW, 1] -= 80.0
            euler[:, _R_ELBOW, 1] += 80.0
            trans[:, 1] -= 0.03 * (1 - np.cos(2 * phase)) / 2
    elif action == "jump":
        height = rng.uniform(0.25, 0.35)
        cycle = (u * 2) % 1.0  # two jumps
        crouch = np.sin(np.pi * np.clip(cycle / 0.45, 0, 1)) ** 2  # down and up before take-off
        air = np.where((cycle > 0.45) & (cycle < 0.8), np.sin(np.pi * (cycle - 0.45) / 0.35), 0.0)
        for hip, knee in ((_L_HIP, _L_KNEE), (_R_HIP, _R_KNEE)):
            euler[:, hip, 0] -= 50 * crouch
            euler[:, knee, 0] += 90 * crouch
        euler[:, _SPINE, 0] += 20 * crouch
        euler[:, _L_SHOULDER, 2] += 150 * air
        euler[:, _R_SHOULDER, 2] -= 150 * air
        trans[:, 1] += -0.25 * crouch + height * air
    elif action == "squat":
        depth = rng.uniform(0.40, 0.48)
        down = _smoothstep(u / 0.3) * (1 - _smoothstep((u - 0.75) / 0.25))
        for hip, knee in ((_L_HIP, _L_KNEE), (_R_HIP, _R_KNEE)):
            euler[:, hip, 0] -= 100 * down
            euler[:, knee, 0] += 120 * down
        euler[:, _SPINE, 0] += 25 * down
        euler[:, _L_SHOULDER, 1] -= 60 * down  # arms forward for balance
        euler[:, _R_SHOULDER, 1] += 60 * down
        trans[:, 1] -= depth * down
    elif action == "kick":
        kicks = int(rng.integers(2, 4))
        cycle = (u * kicks) % 1.0
        swing = np.sin(np.pi * np.clip((cycle - 0.2) / 0.6, 0, 1)) ** 2
        hip, knee = (_L_HIP, _L_KNEE) if side > 0 else (_R_HIP, _R_KNEE)
        euler[:, hip, 0] -= rng.uniform(85, 100) * swing
        euler[:, knee, 0] += 40 * np.sin(np.pi * np.clip((cycle - 0.2) / 0.6, 0, 1)) * (1 - swing)
        euler[:, _SPINE, 0] -= 10 * swing  # lean back
        euler[:, _L_SHOULDER, 2] += 30 * swing
        euler[:, _R_SHOULDER, 2] -= 30 * swing
    else:  # wave: one hand up above the head, the forearm waving
        raise_ = _smoothstep(u / 0.2) * (1 - _smoothstep((u - 0.9) / 0.1))
        shoulder, elbow = (_L_SHOULDER, _L_ELBOW) if side > 0 else (_R_SHOULDER, _R_ELBOW)
        wave = np.sin(2 * np.pi * rng.uniform(1.5, 2.2) * t)
        euler[:, shoulder, 2] += side * 220 * raise_  # from 70 down to 150 up
        euler[:, elbow, 2] += side * (30 + 35 * wave) * raise_
    euler[:, 0, 1] += heading
    rotations = euler_to_matrix(torch.from_numpy(np.radians(euler)), "XYZ")
    poses = matrix_to_axis_angle(rotations).numpy()
    return MotionData(fps=fps, skeleton="smpl24", poses=poses.astype(np.float32), trans=trans, scaling=1.0)
