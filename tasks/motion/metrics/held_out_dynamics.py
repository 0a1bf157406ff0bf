"""Amplitude and jitter of held-out motions beside their ground truth and two baselines, for the demos.

For every held-out motion (generated for something never seen in training: music, a caption) and its
ground truth, the ratios of :func:`~.dynamics.dynamics_ratios` (root-relative motion amplitude and mean
joint acceleration, each divided by the ground truth's) are computed for four columns alike:

- ``dance``: the generated motion;
- ``ground_truth``: the truth itself (1 and 1 by definition: the scale the others are read on);
- ``mean_pose``: the training poses' mean, held still (0 and 0: the timid extreme);
- ``random_clip``: a training motion played as it is (the figure is the mean over every training motion).

Each figure is the mean over the held-out motions. A timid dance has an amplitude ratio near the mean
pose's 0, a trembling one a jitter ratio above the truth's 1; :func:`~.dynamics.dynamics_checks` holds the
dance to the targets.
"""

from __future__ import annotations

import torch

from skeleton_mamba.tasks.motion.metrics.dynamics import DYNAMICS_METRICS, dynamics_checks, dynamics_ratios

__all__ = ["DYNAMICS_COLUMNS", "format_dynamics", "held_out_dynamics", "held_out_dynamics_checks"]

DYNAMICS_COLUMNS = ("dance", "ground_truth", "mean_pose", "random_clip")


def _mean(rows: list[dict[str, float]]) -> dict[str, float]:
    return {k: sum(r[k] for r in rows) / len(rows) for k in rows[0]}


def held_out_dynamics(
    dances: list[torch.Tensor], truths: list[torch.Tensor], train: list[torch.Tensor], fps: float
) -> dict[str, dict[str, float]]:
    """Column (:data:`DYNAMICS_COLUMNS`) -> ``amplitude_ratio`` / ``jitter_ratio`` -> mean over the motions.

    Args:
        dances: generated joints (T_i, J, 3) per held-out motion (metres).
        truths: their ground truth (T'_i, J, 3) (the lengths may differ: the ratios compare whole motions).
        train: the training motions' joints (T_k, J, 3), the baselines' material.
        fps: frame rate of every motion.

    Examples:
        >>> import torch
        >>> _ = torch.manual_seed(0)
        >>> truth, train = torch.randn(30, 22, 3), [torch.randn(30, 22, 3)]
        >>> scores = held_out_dynamics([0.5 * truth], [truth], train, fps=30.0)
        >>> round(scores["dance"]["amplitude_ratio"], 3), round(scores["ground_truth"]["jitter_ratio"], 3)
        (0.5, 1.0)
        >>> scores["mean_pose"]["amplitude_ratio"]  # a still pose
        0.0
    """
    if len(dances) != len(truths) or not dances or not train:
        raise ValueError("need as many dances as truths (at least one) and at least one training motion")
    poses = torch.cat([clip.reshape(-1, *clip.shape[-2:]) for clip in train]).double()
    mean_pose = poses.mean(dim=0)
    rows: dict[str, list[dict[str, float]]] = {c: [] for c in DYNAMICS_COLUMNS}
    for dance, truth in zip(dances, truths, strict=True):
        rows["dance"].append(dynamics_ratios(dance, truth, fps))
        rows["ground_truth"].append(dynamics_ratios(truth, truth, fps))
        rows["mean_pose"].append(dynamics_ratios(mean_pose.expand(truth.shape[0], -1, -1), truth, fps))
        rows["random_clip"].append(_mean([dynamics_ratios(clip, truth, fps) for clip in train]))
    return {c: _mean(r) for c, r in rows.items()}


def held_out_dynamics_checks(scores: dict[str, dict[str, float]]) -> dict[str, bool]:
    """Whether the ``dance`` column reaches the amplitude and jitter targets.

    Examples:
        >>> scores = {"dance": {"amplitude_ratio": 0.5, "jitter_ratio": 1.0, "high_frequency_ratio": 1.0}}
        >>> held_out_dynamics_checks(scores)["amplitude ratio >= 0.7"]
        False
    """
    return dynamics_checks(scores["dance"])


def format_dynamics(scores: dict[str, dict[str, float]], checks: dict[str, bool] | None = None) -> str:
    """A plain-text table of :func:`held_out_dynamics`' result (and the target checks).

    Examples:
        >>> row = {"amplitude_ratio": 1.0, "jitter_ratio": 1.0, "high_frequency_ratio": 1.0}
        >>> print(format_dynamics({c: row for c in DYNAMICS_COLUMNS}).splitlines()[1])
        motion amplitude / ground truth's         1.000         1.000         1.000         1.000
    """
    width = max(len(n) for n in DYNAMICS_METRICS.values())
    lines = [" " * width + "".join(f"{c:>14}" for c in DYNAMICS_COLUMNS)]
    for key, name in DYNAMICS_METRICS.items():
        lines.append(f"{name:<{width}}" + "".join(f"{scores[c][key]:>14.3f}" for c in DYNAMICS_COLUMNS))
    lines += [f"{'reached' if ok else 'NOT reached'}: {check}" for check, ok in (checks or {}).items()]
    return "\n".join(lines)
