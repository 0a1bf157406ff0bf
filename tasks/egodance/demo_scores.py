"""How good is the demo's dance? Scores of held-out dances beside the ground truth and two baselines.

For every held-out window (a motion source never seen in training) the sampled dance, its ground truth
and two baselines that know the training motions but not the window are scored alike:

- ``mean_pose``: the training motions' mean pose (joint positions in the canonical frame), held still;
- ``random_clip``: a training window played as it is (the figure is the mean over every training window).

Scores (joint positions from FK, metres, y-up, floor at y = 0, 30 fps), means over the held-out windows:

- ``plausibility_m``: root-aligned MPJPE to the nearest training pose, mean over frames
  (:func:`~skeleton_mamba.tasks.motion.metrics.pose_distance.nearest_pose_distance`);
- ``mpjpe_m``: MPJPE to the held-out ground truth, in the canonical frame as the module's test;
- ``beat_align``: BeatAlign with the window's music beats ([Bailando] variant, as the module's test);
- ``beat_margin``: that BeatAlign less its chance, the same motion against the beat grid shifted by 1/10 ...
  9/10 of a beat (:func:`~skeleton_mamba.tasks.motion.metrics.beat_align.beat_align_over_chance`): 0 for a
  motion with no relation to the beat, however regular its own; the target is half the ground truth's;
- ``foot_skating``: [GMD] foot skating ratio; ``penetration_m``: [PhysDiff] ground penetration, on joints
  (:mod:`~skeleton_mamba.tasks.motion.metrics.ground`);
- ``amplitude_ratio`` / ``jitter_ratio``: root-relative motion amplitude and mean joint acceleration as ratios
  to the ground truth's (:mod:`~skeleton_mamba.tasks.motion.metrics.dynamics`): a timid dance has a low
  amplitude ratio, a trembling one a high jitter ratio (the mean pose scores 0 and 0).

:data:`TARGETS` are what the demo should reach (``checks`` in ``demo.json``).
"""

from __future__ import annotations

import torch

from skeleton_mamba.tasks.egodance.representation import FPS
from skeleton_mamba.tasks.motion.metrics.beat_align import beat_align_over_chance
from skeleton_mamba.tasks.motion.metrics.dynamics import DYNAMICS_METRICS, dynamics_checks, dynamics_ratios
from skeleton_mamba.tasks.motion.metrics.ground import foot_skating_ratio, ground_penetration
from skeleton_mamba.tasks.motion.metrics.pose_distance import mpjpe, nearest_pose_distance

__all__ = [
    "COLUMNS",
    "METRICS",
    "PLAUSIBILITY_TARGET_M",
    "format_scores",
    "motion_scores",
    "score_held_out",
    "target_checks",
]

PLAUSIBILITY_TARGET_M = 0.08
COLUMNS = ("dance", "ground_truth", "mean_pose", "random_clip")
METRICS = {  # key -> printed name
    "plausibility_m": "pose plausibility (m, nearest training pose)",
    "mpjpe_m": "MPJPE to the ground truth (m)",
    "beat_align": "BeatAlign with the music",
    "beat_margin": "BeatAlign over chance (beats shifted off)",
    "foot_skating": "foot skating ratio",
    "penetration_m": "ground penetration (m)",
    **DYNAMICS_METRICS,
}


def motion_scores(
    joints: torch.Tensor,
    truth: torch.Tensor,
    beats: torch.Tensor,
    train_poses: torch.Tensor | None,
    fps: float,
) -> dict[str, float]:
    """The :data:`METRICS` of one (T, 24, 3) motion against its truth (T, 24, 3), one-hot music beats (T,)
    and the training poses (N, 24, 3); ``train_poses=None`` for a motion made of training poses, whose
    plausibility is 0 by definition (not searched for: the nearest-pose search over every training pose
    is the slow part of these scores)."""
    plausibility = 0.0 if train_poses is None else float(nearest_pose_distance(joints, train_poses))
    beat_align, chance = beat_align_over_chance(joints, beats, "bailando", fps)
    return {
        "plausibility_m": plausibility,
        "mpjpe_m": float(mpjpe(joints.double(), truth.double())),
        "beat_align": beat_align,
        "beat_margin": beat_align - chance,
        "foot_skating": float(foot_skating_ratio(joints, fps)),
        "penetration_m": float(ground_penetration(joints)),
        **dynamics_ratios(joints, truth, fps),
    }


def _mean(rows: list[dict[str, float]]) -> dict[str, float]:
    return {k: sum(r[k] for r in rows) / len(rows) for k in rows[0]}


def score_held_out(
    dances: list[torch.Tensor],
    truths: list[torch.Tensor],
    beats: list[torch.Tensor],
    train: list[torch.Tensor],
    fps: float = FPS,
) -> dict[str, dict[str, float]]:
    """Column (:data:`COLUMNS`) -> metric -> mean over the held-out windows.

    Args:
        dances: sampled joints (T, 24, 3) per held-out window.
        truths: their ground truth (T, 24, 3).
        beats: their one-hot music beats (T,).
        train: the training windows' joints (T_i, 24, 3), i.e. what the model saw.
    """
    if not (len(dances) == len(truths) == len(beats)) or not dances or not train:
        raise ValueError("need as many dances, truths and beat vectors (at least one) and training windows")
    poses = torch.cat([clip.reshape(-1, *clip.shape[-2:]) for clip in train])
    mean_pose = poses.mean(dim=0)
    rows: dict[str, list[dict[str, float]]] = {c: [] for c in COLUMNS}
    for dance, truth, beat in zip(dances, truths, beats, strict=True):
        t = truth.shape[0]
        rows["dance"].append(motion_scores(dance, truth, beat, poses, fps))
        rows["ground_truth"].append(motion_scores(truth, truth, beat, poses, fps))
        rows["mean_pose"].append(motion_scores(mean_pose.expand(t, -1, -1), truth, beat, poses, fps))
        clips = [clip[:t] for clip in train if clip.shape[0] >= t]
        if not clips:
            raise ValueError(f"no training window has the held-out window's {t} frames")
        rows["random_clip"].append(_mean([motion_scores(c, truth, beat, None, fps) for c in clips]))
    return {c: _mean(r) for c, r in rows.items()}


def target_checks(scores: dict[str, dict[str, float]]) -> dict[str, bool]:
    """Whether the dance reaches the demo's targets."""
    dance = scores["dance"]
    return {
        f"plausibility <= {PLAUSIBILITY_TARGET_M} m": dance["plausibility_m"] <= PLAUSIBILITY_TARGET_M,
        "MPJPE below the mean-pose baseline": dance["mpjpe_m"] < scores["mean_pose"]["mpjpe_m"],
        "MPJPE below the random-clip baseline": dance["mpjpe_m"] < scores["random_clip"]["mpjpe_m"],
        "BeatAlign above the random-clip baseline": dance["beat_align"] > scores["random_clip"]["beat_align"],
        "BeatAlign over chance >= half the ground truth's": (
            dance["beat_margin"] >= 0.5 * scores["ground_truth"]["beat_margin"]
        ),
        **dynamics_checks(dance),
    }


def format_scores(scores: dict[str, dict[str, float]], checks: dict[str, bool] | None = None) -> str:
    """A plain-text table of :func:`score_held_out`'s result (and the target checks)."""
    name_width = max(len(n) for n in METRICS.values())
    lines = [" " * name_width + "".join(f"{c:>14}" for c in COLUMNS)]
    for key, name in METRICS.items():
        lines.append(f"{name:<{name_width}}" + "".join(f"{scores[c][key]:>14.3f}" for c in COLUMNS))
    for check, ok in (checks or {}).items():
        lines.append(f"{'reached' if ok else 'NOT reached'}: {check}")
    return "\n".join(lines)
