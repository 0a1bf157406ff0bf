"""Checkpoints saved before the config dataclasses (flat EMM arguments) keep loading.

Until ``EMMConfig``, ``EgoDanceModule`` took EMM's settings as flat arguments and LightningCLI stored them
flat in the checkpoint's hyperparameters. :data:`FLAT_HPARAMS` is what ``sm fit --recipe egodance_demo.yaml
--model.init_args.encoder_dropout 0.2 --model.init_args.head_source none
--model.init_args.use_head_estimator false`` stored then (captured from that code, tiny backbone trimmed to
the fields that differ from the defaults); the weights come from a module built with the new ``network``
argument, whose parameter names and shapes are those of the old one.
"""

from __future__ import annotations

import copy
import functools
import warnings

import lightning
import lightning.pytorch
import pytest
import torch

from skeleton_mamba.cli import main as sm_main
from skeleton_mamba.tasks.checkpoints import load_module
from skeleton_mamba.tasks.egodance.model import EMMConfig
from skeleton_mamba.tasks.egodance.module import EgoDanceModule

TINY_BACKBONE = {
    "skeleton": "smpl24",
    "dim": 16,
    "depth": 1,
    "group_paths": [[1, 2, 0, 3, 4]],
    "heads": 2,
    "mlp_dim": 32,
    "mixer": {"d_state": 16, "headdim": 8, "chunk_size": 16, "A_init_range": [1.0, 16.0]},
}
RESNET = {"embedding_size": 8, "hidden_sizes": [8, 16], "depths": [1, 1], "layer_type": "basic"}
FLAT_HPARAMS = {
    "_class_path": "skeleton_mamba.tasks.egodance.module.EgoDanceModule",
    "context_dim": 32, "music_dim": 35, "use_vision": True, "resnet_path": None, "resnet_layers": RESNET,
    "image_size": 64, "freeze_resnet": False, "encoder_layers": 2, "fusion_layers": 2, "heads": 2,
    "transformer_ff": 64, "encoder_dropout": 0.2, "diffusion_steps": 100, "cond_drop_prob": 0.25,
    "reconstruction": "l2", "lambda_pos": 1.0, "lambda_vel": 0.1, "lambda_contact": 1.0,
    "contact_threshold": 0.95, "lambda_align": 0.01, "align_temperature": 0.07, "lr": 0.001,
    "weight_decay": 0.02, "ema_decay": 0.99, "ema_every": 1, "sampler": "ddim", "sampling_steps": 10,
    "guidance_weight": 2.0, "head_guidance_weight": 0.05, "head_guidance_steps": 1, "head_source": "none",
    "use_head_estimator": False, "lambda_head": 1.0, "test_oracle_head": True, "seed": 0, "protocol": "edge",
    "_instantiator": "lightning.pytorch.cli.instantiate_module",
    "backbone": TINY_BACKBONE,
    "head_estimator": {"input_size": 32, "channels": [16, 32, 32], "dim": 32, "layers": 1},
}  # fmt: skip
NETWORK = EMMConfig(
    context_dim=32, resnet_layers=RESNET, freeze_resnet=False, heads=2, transformer_ff=64, dropout=0.2
)


@pytest.fixture
def flat_checkpoint(tmp_path):
    """A checkpoint with the flat hyperparameters, and the module whose weights it holds."""
    torch.manual_seed(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # random ResNet
        module = EgoDanceModule(
            backbone=TINY_BACKBONE,
            network=NETWORK,
            image_size=64,
            diffusion_steps=100,
            head_source="none",
            use_head_estimator=False,
        )
    path = tmp_path / "flat.ckpt"
    checkpoint = {"state_dict": module.state_dict(), "hyper_parameters": copy.deepcopy(FLAT_HPARAMS)}
    torch.save({**checkpoint, "pytorch-lightning_version": lightning.__version__}, path)
    return path, module


def _same_module(loaded: EgoDanceModule, reference: EgoDanceModule) -> None:
    assert loaded.model.config == NETWORK
    assert loaded.hparams["network"]["dropout"] == 0.2
    assert "encoder_dropout" not in loaded.hparams and "context_dim" not in loaded.hparams
    assert loaded.model.vision_encoder.image_size == 64
    expected = reference.state_dict()
    assert loaded.state_dict().keys() == expected.keys()
    for key, value in loaded.state_dict().items():
        assert torch.equal(value, expected[key]), key


def test_load_from_checkpoint_maps_flat_network_hparams(flat_checkpoint):
    path, reference = flat_checkpoint
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _same_module(EgoDanceModule.load_from_checkpoint(path, weights_only=True), reference)


def test_sm_dance_loader_reads_a_flat_checkpoint(flat_checkpoint):
    path, reference = flat_checkpoint
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _same_module(load_module(EgoDanceModule, path), reference)


def test_sm_test_ckpt_path_builds_the_flat_checkpoints_network(flat_checkpoint, monkeypatch):
    """``sm test --recipe egodance_demo.yaml --ckpt_path FLAT``: the checkpoint's flat settings win over the
    recipe's ``network`` (as every checkpoint hyperparameter wins over the recipe)."""
    path, reference = flat_checkpoint
    tested = []

    @functools.wraps(lightning.pytorch.Trainer.test)  # the CLI reads its options from the signature
    def record(self, model=None, *args, **kwargs):
        tested.append(model)

    monkeypatch.setattr(lightning.pytorch.Trainer, "test", record)
    args = ["test", "--recipe", "egodance_demo.yaml", "--ckpt_path", str(path), "--trainer.logger", "false"]
    args += ["--data.init_args.root", str(path.parent / "data")]  # not read: Trainer.test is replaced
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert sm_main(args) == 0
    (model,) = tested
    assert model.model.config == NETWORK  # the demo recipe's network has transformer_ff 64 too, dropout 0.1
    assert model.hparams.image_size == 64 and model.hparams.fps == 30  # linked from the data module
    _ = reference  # the weights are loaded by Trainer.test itself (replaced here)


def test_unknown_flat_arguments_are_still_errors():
    with pytest.raises(TypeError, match="contxt_dim"):
        EgoDanceModule(contxt_dim=8, head_source="none")
