"""The EgoMusic demo's outcome is fixed by the recipe: a fixed number of optimizer steps (no wall-clock cut),
and with ``--seed_everything`` fixed, two runs write the same scores (``demo.json``) to 3 decimals."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from skeleton_mamba.tasks.training.cli import main as sm_main
from skeleton_mamba.tasks.training.recipe_resolution import packaged_recipes

TINY = [
    "--trainer.max_steps", "3", "--trainer.val_check_interval", "3", "--trainer.enable_progress_bar", "false",
    "--data.init_args.count", "15", "--data.init_args.duration_s", "6.0",
]  # fmt: skip


def _recipe(name: str) -> dict:
    return yaml.safe_load(Path(packaged_recipes()[name]).read_text(encoding="utf-8"))


@pytest.mark.parametrize("name", ["egodance_demo.yaml", "humanml3d_demo.yaml", "stream_dance_demo.yaml"])
def test_demo_recipes_train_a_fixed_schedule_not_a_time_budget(name):
    trainer = _recipe(name)["trainer"]
    assert "max_time" not in trainer
    assert trainer.get("max_steps", -1) > 0 or trainer.get("max_epochs", -1) > 0


@pytest.mark.slow  # about 50 s of CPU (building a 15-dance set, 2 x 3 steps, sampling, scoring, rendering)
def test_two_seeded_demo_runs_print_the_same_scores(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scores = []
    for run in range(2):
        args = ["fit", "--recipe", "egodance_demo.yaml", "--seed_everything", "7", *TINY]
        assert sm_main(args) == 0
        demo = json.loads(Path(f"runs/egodance_demo/version_{run}/demo/demo.json").read_text())
        assert demo["global_step"] == 3
        columns = {c: m for c, m in demo["scores"].items() if isinstance(m, dict)}
        scores.append({c: {k: round(v, 3) for k, v in m.items()} for c, m in columns.items()})
    assert scores[0] == scores[1]
    assert {"amplitude_ratio", "jitter_ratio"} <= set(scores[0]["dance"])
