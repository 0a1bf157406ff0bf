"""Is a long-form dance one dance? Scores of a whole sequence against its windows, and at its seams.

A long track is sampled as overlapping windows joined into one sequence (:func:`.sampling.sample_long_dance`).
Two things can go wrong where the windows meet, and one over the whole length:

- :func:`seam_ratios`: the dance jumps or shakes where one window hands over to the next. At the seam
  frames (:func:`seam_frames`: where each window's overlap with the one before begins and ends) the mean
  joint speed ``|p_{t+1} - p_t| fps``, the mean joint acceleration ``|p_{t+1} - 2 p_t + p_{t-1}| fps^2``
  and the root's horizontal step ``|r_{t+1} - r_t|`` are divided by their means over every other frame:
  a seamless dance scores about 1. :data:`SEAM_TARGETS` holds them to 1.5, 1.5 and 2.
- :func:`long_form_checks`: the windows after the first dance worse than windows sampled afresh, because
  each continues the dance before it. The whole sequence is cut into window-long segments (the demo: one
  where each window starts, :func:`.long_demo.score_long_dance`), and each segment of
  the dance and of the ground truth is put in its own first frame's canonical frame (:func:`segments`: root
  at x = z = 0, facing +z when the model's windows do), exactly as a window sampled alone is scored; their
  MPJPE over the whole length must stay below the mean-pose baseline's and within
  :data:`WHOLE_TO_WINDOWS_TARGET` (10 %) of the mean MPJPE of the same segments sampled alone (the demo: the
  same windows with the same noise, nothing in-painted).

Where the whole dance goes over the minute is reported beside them (:func:`drift`): the world-frame MPJPE,
the head's heading error over the last window and the root's distance from the truth's. Each window's frame
is found from the one before, so without an anchor an error in one window's turn is carried by all later
ones; where the egocentric video holds the heading (the head's turns read from it, :mod:`.video_rotation`;
[EgoMusic] takes the head's world trajectory from SLAM), the heading error at the end of the song must stay
within :data:`END_HEADING_TARGET_DEG`. The root's path has no anchor and no target.
"""

from __future__ import annotations

import torch

from skeleton_mamba.tasks.egodance.heading_frames import HeadingFrames, head_heading, head_rotation
from skeleton_mamba.tasks.egodance.representation import motion_joints

__all__ = [
    "SEAM_METRICS",
    "SEAM_TARGETS",
    "END_HEADING_TARGET_DEG",
    "WHOLE_TO_WINDOWS_TARGET",
    "drift",
    "long_form_checks",
    "segments",
    "seam_frames",
    "seam_ratios",
]

SEAM_TARGETS = {"speed_ratio": 1.5, "acceleration_ratio": 1.5, "root_step_ratio": 2.0}
SEAM_METRICS = {  # key -> printed name
    "speed_ratio": "seam joint speed / elsewhere",
    "acceleration_ratio": "seam joint acceleration / elsewhere (seam jitter)",
    "root_step_ratio": "seam root step / elsewhere",
}
WHOLE_TO_WINDOWS_TARGET = 1.1  # whole-sequence MPJPE at most 10 % above its windows sampled alone
END_HEADING_TARGET_DEG = 30.0  # where the video holds the heading, the head's heading at the end of the song


def seam_frames(starts: list[int], overlap: int, total: int) -> list[int]:
    """The frames around each hand-over of windows starting at ``starts``: for every window but the first,
    the frame before its overlap, its first, its last overlap frame and the one after (within 1..total-2,
    where speed and acceleration are both defined)."""
    frames = set()
    for start in starts[1:]:
        frames.update((start - 1, start, start + overlap - 1, start + overlap))
    return sorted(f for f in frames if 1 <= f <= total - 2)


def _ratio(values: torch.Tensor, seams: torch.Tensor) -> float:
    """mean over the seam frames / mean over the others (NaN without either or with a still dance)."""
    mask = torch.zeros(values.shape[0], dtype=torch.bool)
    mask[seams] = True
    if not mask.any() or mask.all():
        return float("nan")
    elsewhere = float(values[~mask].mean())
    return float(values[mask].mean()) / elsewhere if elsewhere > 0 else float("nan")


def seam_ratios(joints: torch.Tensor, seams: list[int], fps: float, root: int = 0) -> dict[str, float]:
    """Joints (T, J, 3) in metres and the seam frames -> the ratios of :data:`SEAM_METRICS`."""
    if joints.ndim != 3 or joints.shape[-1] != 3 or joints.shape[0] < 3:
        raise ValueError(f"joints must be (T >= 3, J, 3), got {tuple(joints.shape)}")
    j = joints.double()
    t = j.shape[0]
    speed = torch.zeros(t, dtype=j.dtype)
    speed[:-1] = (j[1:] - j[:-1]).norm(dim=-1).mean(-1) * fps
    accel = torch.zeros(t, dtype=j.dtype)
    accel[1:-1] = (j[2:] - 2 * j[1:-1] + j[:-2]).norm(dim=-1).mean(-1) * fps**2
    step = torch.zeros(t, dtype=j.dtype)
    step[:-1] = (j[1:, root, [0, 2]] - j[:-1, root, [0, 2]]).norm(dim=-1)
    inner = torch.arange(1, t - 1)  # frames where all three are defined
    at = torch.tensor([s - 1 for s in seams], dtype=torch.long)
    return {
        "speed_ratio": _ratio(speed[inner], at),
        "acceleration_ratio": _ratio(accel[inner], at),
        "root_step_ratio": _ratio(step[inner], at),
    }


def segments(tokens: torch.Tensor, starts: list[int], window: int, turn: bool) -> torch.Tensor:
    """(T, 24, 10) motion tokens -> (S, window, 24, 10): the segments starting at ``starts``, each in its own
    first frame's canonical frame (:class:`.heading_frames.HeadingFrames`; ``turn``: facing +z)."""
    frames = HeadingFrames(turn)
    cut = torch.stack([tokens[s : s + window] for s in starts])
    return frames.to_frame(cut, frames.relative_frame(cut[:, 0]))


def drift(tokens: torch.Tensor, truth: torch.Tensor, window: int) -> dict[str, float]:
    """Where a long dance (T, 24, 10) ends up against its truth, both in the sequence's first frame: MPJPE
    over the whole length (m), and over its last ``window`` frames the mean absolute heading error of the
    head (degrees) and the root's mean horizontal distance from the truth's (m)."""
    dance_joints, true_joints = motion_joints(tokens).double(), motion_joints(truth).double()
    heading = head_heading(head_rotation(tokens[-window:].double())) - head_heading(
        head_rotation(truth[-window:].double())
    )
    heading = torch.remainder(heading + torch.pi, 2 * torch.pi) - torch.pi
    root = (dance_joints[-window:, 0, [0, 2]] - true_joints[-window:, 0, [0, 2]]).norm(dim=-1)
    return {
        "world_mpjpe_m": float((dance_joints - true_joints).norm(dim=-1).mean()),
        "end_heading_error_deg": float(torch.rad2deg(heading.abs()).mean()),
        "end_root_distance_m": float(root.mean()),
    }


def long_form_checks(scores: dict) -> dict[str, bool]:
    """Whether a long-form dance's ``scores`` (``mpjpe_m``, ``windows_alone_mpjpe_m``,
    ``mean_pose_mpjpe_m`` and the :func:`seam_ratios` under ``seams``) reach the targets."""
    whole, alone = scores["mpjpe_m"], scores["windows_alone_mpjpe_m"]
    checks = {
        "whole-sequence MPJPE below the mean-pose baseline": whole < scores["mean_pose_mpjpe_m"],
        f"whole-sequence MPJPE within {WHOLE_TO_WINDOWS_TARGET:g}x of its windows sampled alone": (
            whole <= WHOLE_TO_WINDOWS_TARGET * alone
        ),
    }
    for key, target in SEAM_TARGETS.items():
        checks[f"{SEAM_METRICS[key]} <= {target:g}"] = scores["seams"][key] <= target
    if scores.get("heading_source") == "video":
        error = scores["drift"]["end_heading_error_deg"]
        checks[f"end-of-song heading error <= {END_HEADING_TARGET_DEG:g} degrees (held by the video)"] = (
            error <= END_HEADING_TARGET_DEG
        )
    return checks
