"""QEAN checkpoints saved before ``network`` (flat QEANConfig arguments) keep loading.

Until ``QEANModule`` took ``network: QEANConfig``, it took QEAN's sizes and window lengths as flat arguments
and LightningCLI stored them flat in the checkpoint's hyperparameters. :data:`FLAT_HPARAMS` is what ``sm fit
--recipe qean.yaml`` with ``--model.init_args.{hidden=32,heads=2,motion_layers=1,audio_layers=1,
cross_layers=1,mlp_dim=64,num_periods=2,dropout=0.0,output_dir=predictions,seed_frames=12,music_frames=24,
predict_frames=4,generate_frames=20}`` (and the same lengths on the data module) stored then, captured from
that code; the weights come from a module built with the new ``network`` argument, whose parameter names and
shapes are those of the old one.
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
from skeleton_mamba.tasks.qean.model import QEANConfig
from skeleton_mamba.tasks.qean.module import QEANModule

FLAT_HPARAMS = {
    "_class_path": "skeleton_mamba.tasks.qean.module.QEANModule",
    "hidden": 32, "heads": 2, "motion_layers": 1, "audio_layers": 1, "cross_layers": 1, "mlp_dim": 64,
    "dropout": 0.0, "num_periods": 2, "conv_kernel": 3, "rotary_base": 10000.0, "learned_positions": False,
    "seed_frames": 12, "music_frames": 24, "predict_frames": 4, "lr": 0.0001,
    "lr_milestones": [90000, 150000], "lr_gamma": 0.1, "generate_frames": 20, "audio_chunk": 32,
    "output_dir": "predictions", "render": True, "protocol": "fact",
    "_instantiator": "lightning.pytorch.cli.instantiate_module", "backbone": None,
}  # fmt: skip
NETWORK = QEANConfig(
    hidden=32, heads=2, motion_layers=1, audio_layers=1, cross_layers=1, mlp_dim=64, dropout=0.0,
    num_periods=2, seed_frames=12, music_frames=24, predict_frames=4,
)  # fmt: skip
LENGTHS = {"seed_frames": 12, "music_frames": 24, "predict_frames": 4, "generate_frames": 20}


@pytest.fixture
def flat_checkpoint(tmp_path):
    """A checkpoint with the flat hyperparameters, and the module whose weights it holds."""
    torch.manual_seed(0)
    module = QEANModule(network=NETWORK, generate_frames=20, output_dir="predictions")
    path = tmp_path / "flat.ckpt"
    checkpoint = {"state_dict": module.state_dict(), "hyper_parameters": copy.deepcopy(FLAT_HPARAMS)}
    torch.save({**checkpoint, "pytorch-lightning_version": lightning.__version__}, path)
    return path, module


def _same_module(loaded: QEANModule, reference: QEANModule) -> None:
    assert loaded.model.config == NETWORK
    assert loaded.hparams["network"]["hidden"] == 32 and loaded.hparams["network"]["seed_frames"] == 12
    assert "hidden" not in loaded.hparams and "seed_frames" not in loaded.hparams
    assert loaded.hparams.generate_frames == 20 and loaded.hparams.output_dir == "predictions"
    assert loaded.test_evaluation.protocol.seed_frames == 12  # FACT's scores start after the seed
    expected = reference.state_dict()
    assert loaded.state_dict().keys() == expected.keys()
    for key, value in loaded.state_dict().items():
        assert torch.equal(value, expected[key]), key


def test_load_from_checkpoint_maps_flat_network_hparams(flat_checkpoint):
    path, reference = flat_checkpoint
    _same_module(QEANModule.load_from_checkpoint(path, weights_only=True), reference)


@pytest.mark.parametrize("subcommand", ["predict", "test"])
def test_sm_ckpt_path_builds_the_flat_checkpoints_network(flat_checkpoint, monkeypatch, subcommand):
    """``sm predict|test --recipe qean.yaml --ckpt_path FLAT``: the checkpoint's flat settings win over the
    recipe's ``network`` (hidden 800 ...), as every checkpoint hyperparameter wins over the recipe."""
    path, reference = flat_checkpoint
    called = []
    method = getattr(lightning.pytorch.Trainer, subcommand)

    @functools.wraps(method)  # the CLI reads its options from the signature
    def record(self, model=None, *args, **kwargs):
        called.append(model)

    monkeypatch.setattr(lightning.pytorch.Trainer, subcommand, record)
    root = path.parent / "aistpp"
    for folder in ("motions", "music"):  # the layout the data module checks; not read (method replaced)
        (root / folder).mkdir(parents=True)
    args = [subcommand, "--recipe", "qean.yaml", "--ckpt_path", str(path), "--trainer.logger", "false"]
    args += [f"--data.init_args.root={root}", *(f"--data.init_args.{k}={v}" for k, v in LENGTHS.items())]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert sm_main(args) == 0
    (model,) = called
    assert model.model.config == NETWORK
    assert model.hparams.generate_frames == 20
    _ = reference  # the weights are loaded by the Trainer method itself (replaced here)


def test_unknown_flat_arguments_are_still_errors():
    with pytest.raises(TypeError, match="hiden"):
        QEANModule(hiden=8)
