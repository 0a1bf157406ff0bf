"""Motions for tests: rest poses, SMPL motions, NTU bodies, a BVH."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance

# Rest offsets of the SMPL skeleton (Stanford-TML/EDGE vis.py), y-up.
PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]


OFFSETS = np.array([
    [0, 0, 0], [0.0586, -0.0823, -0.0177], [-0.0603, -0.0905, -0.0135], [0.0044, 0.1244, -0.0384],
    [0.0435, -0.3865, 0.0080], [-0.0433, -0.3837, -0.0048], [0.0045, 0.1380, 0.0268],
    [-0.0148, -0.4269, -0.0374], [0.0191, -0.4200, -0.0346], [-0.0023, 0.0560, 0.0029],
    [0.0411, -0.0603, 0.1220], [-0.0348, -0.0621, 0.1303], [-0.0134, 0.2116, -0.0335],
    [0.0717, 0.1140, -0.0189], [-0.0830, 0.1125, -0.0237], [0.0101, 0.0889, 0.0504],
    [0.1229, 0.0452, -0.0190], [-0.1132, 0.0469, -0.0085], [0.2553, -0.0156, -0.0229],
    [-0.2601, -0.0144, -0.0313], [0.2657, 0.0127, -0.0074], [-0.2691, 0.0068, -0.0060],
    [0.0867, -0.0106, -0.0156], [-0.0888, -0.0087, -0.0101],
])  # fmt: skip


def rest_pose() -> np.ndarray:
    """(24, 3) joints of the rest pose with the pelvis at the origin."""
    joints = np.zeros((24, 3))
    for j in range(1, 24):
        joints[j] = joints[PARENTS[j]] + OFFSETS[j]
    return joints


def published_kinetic(positions: np.ndarray, bug: bool, fps: float = 60.0) -> np.ndarray:
    """Loop transcription of aistplusplus_api kinetic.py/utils.py, y-up, window 2."""
    dt, w, t_len = 1.0 / fps, 2, len(positions)
    out = []
    for j in range(positions.shape[1]):
        ke_h = ke_v = ee = 0.0
        for i in range(1, t_len):
            ks = [k for k in range(-w, w + 1) if i + k - 1 >= 0 and i + k < t_len]
            v = sum(positions[i + k, j] - positions[i + k - 1, j] for k in ks) / (len(ks) * dt)
            ke_h += v[0] ** 2 + v[2] ** 2
            ke_v += v[1] ** 2
            ks = [k for k in range(-w, w + 1) if i + k - 1 >= 0 and i + k + 1 < t_len]
            acc = np.zeros(3)
            for k in ks:
                p_prev, p, p_next = positions[i + k - 1, j], positions[i + k, j], positions[i + k + 1, j]
                v1 = p - p_prev / dt if bug else (p - p_prev) / dt
                acc += ((p_next - p) / dt - v1) / dt
            ee += np.linalg.norm(acc / len(ks))
        out += [ke_h / (t_len - 1), ke_v / (t_len - 1), ee / (t_len - 1)]
    return np.array(out)


def _smpl_motion(frames: int = 25) -> MotionData:
    rng = np.random.default_rng(3)
    poses = rng.normal(0, 0.6, (frames, 72)).astype(np.float32)
    trans = (rng.normal(0, 0.5, (frames, 3)) + [0, 0.9, 0]).astype(np.float32)
    return MotionData(30.0, poses=poses, trans=trans * 2.0, scaling=2.0)


# A standing person, 25 Kinect v2 joints (x, y, z) in metres: taller than wide, as real bodies are.
STANDING = np.array(
    [[0.0, 0.0, 3.0], [0.0, 0.3, 3.0], [0.0, 0.55, 3.0], [0.0, 0.7, 3.0], [-0.18, 0.5, 3.0],
     [-0.2, 0.25, 3.0], [-0.2, 0.05, 3.0], [-0.2, 0.0, 3.0], [0.18, 0.5, 3.0], [0.2, 0.25, 3.0],
     [0.2, 0.05, 3.0], [0.2, 0.0, 3.0], [-0.1, -0.05, 3.0], [-0.1, -0.45, 3.0], [-0.1, -0.85, 3.0],
     [-0.1, -0.9, 2.9], [0.1, -0.05, 3.0], [0.1, -0.45, 3.0], [0.1, -0.85, 3.0], [0.1, -0.9, 2.9],
     [0.0, 0.5, 3.0], [-0.2, -0.05, 3.0], [-0.22, 0.0, 3.0], [0.2, -0.05, 3.0], [0.22, 0.0, 3.0]]
)  # fmt: skip


def body_motion(num_frames: int, amplitude: float, shift: float = 0.0, seed: int = 0) -> np.ndarray:
    """(T, 25, 3) joints of a standing person whose hands wave with the given amplitude."""
    rng = np.random.default_rng(seed)
    t = np.arange(num_frames)[:, None]
    xyz = np.repeat(STANDING[None], num_frames, 0) + [shift, 0.0, 0.0]
    xyz[:, [6, 7, 10, 11, 21, 22, 23, 24], 1] += amplitude * np.sin(t / 5.0)
    return xyz + rng.normal(0, 1e-3, xyz.shape)


def skeleton_text(frames: list[list[tuple[int, np.ndarray]]], newline: str = "\r\n") -> str:
    """The official ``.skeleton`` text layout for ``frames`` = [[(bodyID, (25, 3) xyz), ...], ...]."""
    out = [str(len(frames))]
    for bodies in frames:
        out.append(str(len(bodies)))
        for body_id, xyz in bodies:
            out.append(f"{body_id} 0 1 1 1 1 0 0.02764709 0.05745083 2")
            out.append("25")
            for j, (x, y, z) in enumerate(xyz):
                depth = f"{250 + 60 * x / z:.4f} {212 - 60 * y / z:.4f}"
                color = f"{960 + 250 * x / z:.3f} {540 - 250 * y / z:.3f}"
                out.append(f"{x:.7g} {y:.7g} {z:.7g} {depth} {color} 0.5 0.5 -0.5 0.5 {1 + j % 2}")
    return newline.join(out) + newline


def write_skeleton(path: Path, frames: list[list[tuple[int, np.ndarray]]], newline: str = "\r\n") -> Path:
    path.write_bytes(skeleton_text(frames, newline).encode("ascii"))
    return path


def as_written(xyz: np.ndarray) -> np.ndarray:
    """The float32 values a reader gets back from the ``%.7g`` text."""
    return np.array([[float(f"{v:.7g}") for v in row] for row in xyz], dtype=np.float32)


HAND_BVH = """HIERARCHY
ROOT root
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition {order}
  JOINT child
  {{
    OFFSET 1 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {{
      OFFSET 0 2 0
    }}
  }}
}}
MOTION
Frames: 1
Frame Time: 0.04
{values}
"""


def _motion(folder, name="synthetic_bounce_120bpm_s1", seconds=2.0):
    return save_motion(folder / f"{name}.npz", synthesize_dance(120, seconds, 10.0, "bounce", 1))
