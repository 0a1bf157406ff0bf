"""Shared test fixtures."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest
import torch

from tests.helpers.repo import SHARED_DATA

# The suite runs under pytest-xdist with one worker per core: one intra-op thread per worker
# avoids oversubscription, which slows small ops down by an order of magnitude.
torch.set_num_threads(1)


@pytest.fixture(scope="session", autouse=True)
def _remove_keypoint_stores_of_test_files(tmp_path_factory):
    """The recognition data module keeps a memory-mapped copy of each annotation file in the user's cache
    (``keypoints/``): at the end of the session, those of this session's temporary files are removed."""
    yield
    from skeleton_mamba.tasks.motion.io.cache import default_cache_root

    base = tmp_path_factory.getbasetemp().resolve()
    root = default_cache_root() / "keypoints"
    for meta in root.glob("*/store.json"):
        try:
            source = Path(json.loads(meta.read_text())["source"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if source.is_relative_to(base):
            shutil.rmtree(meta.parent, ignore_errors=True)
            (root / f".{meta.parent.name}.lock").unlink(missing_ok=True)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real sample files in ``../shared/data`` (skips the test when the folder is absent)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real sample data not found at {SHARED_DATA} (the project's shared/data folder)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def tiny_egodance_module():
    """A builder of tiny EgoDance modules (random weights, seconds per step on a CPU).

    ``tiny_egodance_module(**overrides)``: keyword arguments replace the tiny defaults.
    """
    from skeleton_mamba.tasks.egodance.model import EMMConfig
    from skeleton_mamba.tasks.egodance.module import (
        DanceSampling,
        EgoDanceModule,
        EvaluationOptions,
        LossOptions,
        OptimizerOptions,
    )

    tiny = {
        "backbone": {
            "dim": 16,
            "depth": 1,
            "heads": 2,
            "mlp_dim": 32,
            "mixer": {"d_state": 8, "headdim": 8, "chunk_size": 16},
        },
        "network": {
            "context_dim": 16,
            "resnet_layers": {
                "embedding_size": 8,
                "hidden_sizes": [8, 16],
                "depths": [1, 1],
                "layer_type": "basic",
            },
            "heads": 2,
            "transformer_ff": 32,
        },
        "image_size": 32,
        "diffusion_steps": 20,
        "sampling": {"sampling_steps": 2},
        "head_estimator": {"input_size": 16, "channels": [8, 8], "dim": 8, "layers": 1},
    }
    network_fields = {f.name for f in dataclasses.fields(EMMConfig)}
    # a field of a config group by its own name, or by the name its group gives it
    renamed = {"lambda_pos": ("kinematic", "pos"), "lambda_vel": ("kinematic", "vel"),
               "lambda_contact": ("kinematic", "contact"), "head_source": ("head_guidance", "source"),
               "head_guidance_weight": ("head_guidance", "weight"),
               "head_guidance_steps": ("head_guidance", "steps"),
               "test_oracle_head": ("head_guidance", "test_oracle")}  # fmt: skip
    groups = {"loss": LossOptions, "optimizer": OptimizerOptions, "sampling": DanceSampling,
              "evaluation": EvaluationOptions}  # fmt: skip
    for group, cls in groups.items():
        renamed.update({f.name: (group, f.name) for f in dataclasses.fields(cls)})

    def build(**overrides) -> EgoDanceModule:
        """Overrides by field name: ``lr=1e-3`` sets ``optimizer.lr``, ``heads=2`` the EMMConfig's."""
        network = {**tiny["network"], **{k: overrides.pop(k) for k in set(overrides) & network_fields}}
        args = {**tiny, "network": network}
        for name in set(overrides) & set(renamed):
            group, field = renamed[name]
            args[group] = {**args.get(group, {}), field: overrides.pop(name)}
        return EgoDanceModule(**{**args, **overrides})

    return build


@pytest.fixture(scope="session", autouse=True)
def _librosa_kernels_compiled() -> None:
    """Compile librosa's numba kernels once, under the inter-process lock, before any test runs.

    Tests also call librosa directly (outside our lock); without this, two xdist workers compiling the
    same kernels at once on a fresh install can crash (see ``tasks/motion/music/jit_lock.py``).
    """
    import numpy as np

    from skeleton_mamba.tasks.motion.music.features import compute_music_features

    noise = np.random.default_rng(0).standard_normal(4 * 30 * 512).astype(np.float32)
    for fps in (60, 30):
        compute_music_features(noise[: 4 * fps * 512], fps=fps)  # tempo estimate path
        compute_music_features(noise[: 4 * fps * 512], fps=fps, start_bpm=120.0)
