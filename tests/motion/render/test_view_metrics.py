"""The viewer's metrics panel: every score by its full name (nested at any depth), whole numbers as such,
booleans as yes / no; lists and long texts left out."""

from __future__ import annotations

import json

from skeleton_mamba.tasks.motion.render.view import listed_metrics


def test_nested_scores_flattened_by_name():
    demo = {
        "synthetic": True,
        "sampler": "ddim",
        "global_step": 400,
        "samples": [{"sample_id": "x"}],
        "label": "x" * 200,
        "scores": {
            "held_out_windows": 12,
            "dance": {"mpjpe_m": 0.077, "beat_align": 0.568},
            "ground_truth": {"mpjpe_m": 0.0},
        },
        "checks": {"plausibility <= 0.08 m": True, "MPJPE below the mean-pose baseline": False},
    }
    listed = listed_metrics(demo)
    assert listed == {
        "synthetic": "yes",
        "sampler": "ddim",
        "global_step": 400,
        "scores.held_out_windows": 12,
        "scores.dance.mpjpe_m": 0.077,
        "scores.dance.beat_align": 0.568,
        "scores.ground_truth.mpjpe_m": 0.0,
        "checks.plausibility <= 0.08 m": "yes",
        "checks.MPJPE below the mean-pose baseline": "no",
    }
    assert isinstance(listed["global_step"], int)
    assert listed_metrics({"x": float("nan"), "y": None}) == {"x": None, "y": None}  # shown as null
    json.dumps(listed, allow_nan=False)  # the page's JSON holds no NaN
