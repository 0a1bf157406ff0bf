"""Does the text-to-motion demo generate plausible motion, and does the caption matter?

For a few held-out captions the demo generates a few motions each (joints (T, 22, 3), metres, y-up) and
scores them against the training clips' poses:

- ``plausibility_m``: root-aligned MPJPE to the nearest training pose, mean over frames and motions
  (:func:`~skeleton_mamba.tasks.motion.metrics.pose_distance.nearest_pose_distance`);
- ``within_caption_m``: :func:`~skeleton_mamba.tasks.motion.metrics.pose_distance.pose_set_distance`
  between two motions of the same caption, mean over captions and pairs;
- ``between_captions_m``: the same between motions of different captions.

The caption matters when motions of different captions lie farther apart than motions of one caption. And
whether a prompt's action shows: for prompts worded as no training caption is (:data:`~.actions.PARAPHRASES`),
the action :func:`~.actions.read_action` reads from each generated motion against the prompt's
(:func:`action_scores`; target: :data:`ACTION_TARGET` of the prompts).
"""

from __future__ import annotations

from itertools import combinations

import torch

from skeleton_mamba.tasks.motion.metrics.pose_distance import nearest_pose_distance, pose_set_distance
from skeleton_mamba.tasks.text2motion.actions import read_action

__all__ = [
    "ACTION_TARGET",
    "PLAUSIBILITY_TARGET_M",
    "action_checks",
    "action_scores",
    "caption_checks",
    "caption_scores",
    "format_action_scores",
    "format_caption_scores",
]

PLAUSIBILITY_TARGET_M = 0.08


def _mean(values: list[torch.Tensor]) -> float:
    return float(torch.stack(values).mean())


def caption_scores(motions: dict[str, list[torch.Tensor]], train_poses: torch.Tensor) -> dict[str, float]:
    """Scores of ``caption -> [motion (T, J, 3), ...]`` (at least 2 captions, 2 motions each) against the
    training poses (N, J, 3)."""
    groups = list(motions.values())
    if len(groups) < 2 or any(len(g) < 2 for g in groups):
        raise ValueError("need at least two captions with at least two motions each")
    within = [pose_set_distance(a, b) for g in groups for a, b in combinations(g, 2)]
    between = [pose_set_distance(a, b) for g, h in combinations(groups, 2) for a in g for b in h]
    return {
        "plausibility_m": _mean([nearest_pose_distance(m, train_poses) for g in groups for m in g]),
        "within_caption_m": _mean(within),
        "between_captions_m": _mean(between),
    }


def caption_checks(scores: dict[str, float]) -> dict[str, bool]:
    """Whether the generated motions reach the demo's targets."""
    return {
        f"plausibility <= {PLAUSIBILITY_TARGET_M} m": scores["plausibility_m"] <= PLAUSIBILITY_TARGET_M,
        "the caption matters (between captions > within a caption)": (
            scores["between_captions_m"] > scores["within_caption_m"]
        ),
    }


def format_caption_scores(scores: dict[str, float], checks: dict[str, bool]) -> str:
    """Plain-text lines of the scores and checks."""
    names = {
        "plausibility_m": "pose plausibility (m, nearest training pose)",
        "within_caption_m": "distance of two motions of one caption (m)",
        "between_captions_m": "distance of motions of different captions (m)",
    }
    width = max(len(n) for n in names.values())
    lines = [f"{names[k]:<{width}}{scores[k]:>10.3f}" for k in names]
    lines += [f"{'reached' if ok else 'NOT reached'}: {check}" for check, ok in checks.items()]
    return "\n".join(lines)


ACTION_TARGET = 0.8  # of the paraphrased prompts whose motion shows their action


def action_scores(expected: list[str], joints: list[torch.Tensor]) -> dict:
    """Which action each generated motion shows (:func:`~.actions.read_action` on its joints (T, 22, 3))
    against the action its prompt asked for: ``{"shown": fraction, "per_action": {action: [hits, prompts]},
    "read": [action read or None, ...]}``."""
    read = [read_action(j.numpy()) for j in joints]
    per_action: dict[str, list[int]] = {}
    for want, got in zip(expected, read):
        tally = per_action.setdefault(want, [0, 0])
        tally[0] += int(got == want)
        tally[1] += 1
    shown = sum(hits for hits, _ in per_action.values()) / max(len(expected), 1)
    return {"shown": shown, "per_action": per_action, "read": read}


def action_checks(scores: dict) -> dict[str, bool]:
    return {
        f"paraphrased prompts show their action >= {ACTION_TARGET:.0%}": scores["shown"] >= ACTION_TARGET,
    }


def format_action_scores(scores: dict, checks: dict[str, bool]) -> str:
    """One line per action (hits / prompts), the fraction shown and the checks."""
    lines = [f"  {action:<14}{hits} / {count}" for action, (hits, count) in scores["per_action"].items()]
    lines.append(f"  {'all':<14}{scores['shown']:.0%} of the prompts show their action (read from joints)")
    lines += [f"{'reached' if ok else 'NOT reached'}: {check}" for check, ok in checks.items()]
    return "\n".join(lines)
