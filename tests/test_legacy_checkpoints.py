"""Checkpoints saved before the config dataclasses (flat network arguments) keep loading.

Until ``EMMConfig``, ``EgoDanceModule`` took EMM's settings as flat arguments and LightningCLI stored them
flat in the checkpoint's hyperparameters. :data:`FLAT_HPARAMS` is what ``sm fit --recipe egodance_demo.yaml
--model.init_args.encoder_dropout 0.2 --model.init_args.head_source none
--model.init_args.use_head_estimator false`` stored then (captured from that code, tiny backbone trimmed to
the fields that differ from the defaults). Until ``QEANModule`` took ``network: QEANConfig``, it took QEAN's
sizes and window lengths flat: :data:`QEAN_FLAT_HPARAMS` is what ``sm fit --recipe qean.yaml`` with
``--model.init_args.{hidden=32,heads=2,motion_layers=1,audio_layers=1,cross_layers=1,mlp_dim=64,num_periods=2,
dropout=0.0,output_dir=predictions,seed_frames=12,music_frames=24,predict_frames=4,generate_frames=20}`` (the
same lengths on the data module) stored then, captured from that code. The weights come from modules built
with the new ``network`` argument, whose parameter names and shapes are those of the old ones.
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
from skeleton_mamba.tasks.checkpoints import load_module, load_module_and_checkpoint
from skeleton_mamba.tasks.egodance.model import EMMConfig
from skeleton_mamba.tasks.egodance.module import EgoDanceModule
from skeleton_mamba.tasks.qean.model import QEANConfig
from skeleton_mamba.tasks.qean.module import QEANModule

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
QEAN_FLAT_HPARAMS = {
    "_class_path": "skeleton_mamba.tasks.qean.module.QEANModule",
    "hidden": 32, "heads": 2, "motion_layers": 1, "audio_layers": 1, "cross_layers": 1, "mlp_dim": 64,
    "dropout": 0.0, "num_periods": 2, "conv_kernel": 3, "rotary_base": 10000.0, "learned_positions": False,
    "seed_frames": 12, "music_frames": 24, "predict_frames": 4, "lr": 0.0001,
    "lr_milestones": [90000, 150000], "lr_gamma": 0.1, "generate_frames": 20, "audio_chunk": 32,
    "output_dir": "predictions", "render": True, "protocol": "fact",
    "_instantiator": "lightning.pytorch.cli.instantiate_module", "backbone": None,
}  # fmt: skip
QEAN_NETWORK = QEANConfig(
    hidden=32, heads=2, motion_layers=1, audio_layers=1, cross_layers=1, mlp_dim=64, dropout=0.0,
    num_periods=2, seed_frames=12, music_frames=24, predict_frames=4,
)  # fmt: skip
QEAN_LENGTHS = {"seed_frames": 12, "music_frames": 24, "predict_frames": 4, "generate_frames": 20}


def _save_flat(path, module, hparams: dict):
    """``module``'s weights with ``hparams`` as the checkpoint's hyperparameters, at ``path``."""
    checkpoint = {"state_dict": module.state_dict(), "hyper_parameters": copy.deepcopy(hparams)}
    torch.save({**checkpoint, "pytorch-lightning_version": lightning.__version__}, path)
    return path


def _same_weights(loaded, reference) -> None:
    expected = reference.state_dict()
    assert loaded.state_dict().keys() == expected.keys()
    for key, value in loaded.state_dict().items():
        assert torch.equal(value, expected[key]), key


def _sm_model(monkeypatch, args: list[str]):
    """The model ``sm <subcommand> ARGS`` hands its Trainer method (replaced: nothing runs or loads)."""
    called = []
    method = getattr(lightning.pytorch.Trainer, args[0])

    @functools.wraps(method)  # the CLI reads its options from the signature
    def record(self, model=None, *args, **kwargs):
        called.append(model)

    monkeypatch.setattr(lightning.pytorch.Trainer, args[0], record)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert sm_main([*args, "--trainer.logger", "false"]) == 0
    (model,) = called
    return model


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
    return _save_flat(tmp_path / "flat.ckpt", module, FLAT_HPARAMS), module


def _same_module(loaded: EgoDanceModule, reference: EgoDanceModule) -> None:
    assert loaded.model.config == NETWORK
    assert loaded.hparams["network"]["dropout"] == 0.2
    assert "encoder_dropout" not in loaded.hparams and "context_dim" not in loaded.hparams
    assert loaded.model.vision_encoder.image_size == 64
    _same_weights(loaded, reference)


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
        module, checkpoint = load_module_and_checkpoint(EgoDanceModule, path)  # what `sm dance` calls
    _same_module(module, reference)
    assert checkpoint["state_dict"].keys() == module.state_dict().keys()
    assert checkpoint["hyper_parameters"]["image_size"] == 64


def test_sm_test_ckpt_path_builds_the_flat_checkpoints_network(flat_checkpoint, monkeypatch):
    """``sm test --recipe egodance_demo.yaml --ckpt_path FLAT``: the checkpoint's flat settings win over the
    recipe's ``network`` (as every checkpoint hyperparameter wins over the recipe)."""
    path, reference = flat_checkpoint
    args = ["test", "--recipe", "egodance_demo.yaml", "--ckpt_path", str(path)]
    args += ["--data.init_args.root", str(path.parent / "data")]  # not read: Trainer.test is replaced
    model = _sm_model(monkeypatch, args)
    assert model.model.config == NETWORK  # the demo recipe's network has transformer_ff 64 too, dropout 0.1
    assert model.hparams.image_size == 32 and model.hparams.fps == 30  # linked from the recipe's data module
    _ = reference  # the weights are loaded by Trainer.test itself (replaced here)


def test_unknown_flat_arguments_are_still_errors():
    with pytest.raises(TypeError, match="contxt_dim"):
        EgoDanceModule(contxt_dim=8, head_source="none")


# ----- QEAN -----


@pytest.fixture
def qean_flat_checkpoint(tmp_path):
    """A QEAN checkpoint with the flat hyperparameters, and the module whose weights it holds."""
    torch.manual_seed(0)
    module = QEANModule(network=QEAN_NETWORK, generate_frames=20, output_dir="predictions")
    return _save_flat(tmp_path / "flat.ckpt", module, QEAN_FLAT_HPARAMS), module


def test_qean_load_from_checkpoint_maps_flat_network_hparams(qean_flat_checkpoint):
    path, reference = qean_flat_checkpoint
    loaded = QEANModule.load_from_checkpoint(path, weights_only=True)
    assert loaded.model.config == QEAN_NETWORK
    assert loaded.hparams["network"]["hidden"] == 32 and loaded.hparams["network"]["seed_frames"] == 12
    assert "hidden" not in loaded.hparams and "seed_frames" not in loaded.hparams
    assert loaded.hparams.generate_frames == 20 and loaded.hparams.output_dir == "predictions"
    assert loaded.test_evaluation.protocol.seed_frames == 12  # FACT's scores start after the seed
    _same_weights(loaded, reference)


@pytest.mark.parametrize("subcommand", ["predict", "test"])
def test_qean_sm_ckpt_path_builds_the_flat_checkpoints_network(qean_flat_checkpoint, monkeypatch, subcommand):
    """``sm predict|test --recipe qean.yaml --ckpt_path FLAT``: the checkpoint's flat settings win over the
    recipe's ``network`` (hidden 800 ...), as every checkpoint hyperparameter wins over the recipe."""
    path, reference = qean_flat_checkpoint
    root = path.parent / "aistpp"
    for folder in ("motions", "music"):  # the layout the data module checks; not read (method replaced)
        (root / folder).mkdir(parents=True)
    args = [subcommand, "--recipe", "qean.yaml", "--ckpt_path", str(path), f"--data.init_args.root={root}"]
    model = _sm_model(monkeypatch, [*args, *(f"--data.init_args.{k}={v}" for k, v in QEAN_LENGTHS.items())])
    assert model.model.config == QEAN_NETWORK
    assert model.hparams.generate_frames == 20
    _ = reference  # the weights are loaded by the Trainer method itself (replaced here)


def test_qean_unknown_flat_arguments_are_still_errors():
    with pytest.raises(TypeError, match="hiden"):
        QEANModule(hiden=8)
