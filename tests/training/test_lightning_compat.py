"""The Lightning internals the project still relies on, all in ``tasks/training/lightning_compat.py``.

Checked against lightning 2.5.2 to 2.6.6 (``CHECKED_LIGHTNING``) and jsonargparse 4.53.0
(``CHECKED_JSONARGPARSE``: the import-path policy recipes' class paths go through). These tests fail with a
message naming the private name and that range when a Lightning or jsonargparse release removes or changes
what the adapter builds on, or when LightningCLI stops calling the public hook the adapter is installed from
in the order it needs. Also here:
:func:`~skeleton_mamba.tasks.training.base_module.attached_trainer`, the public replacement of
``module._trainer``.
"""

from __future__ import annotations

import sys

import jsonargparse
import lightning.pytorch as pl
import pytest
import torch
from lightning.pytorch import LightningDataModule, LightningModule
from lightning.pytorch.cli import LightningCLI

from skeleton_mamba.tasks.training import lightning_compat
from skeleton_mamba.tasks.training.base_module import attached_trainer
from skeleton_mamba.tasks.training.lightning_compat import (
    CHECKED_JSONARGPARSE,
    CHECKED_LIGHTNING,
    PRIVATE_NAMES,
    import_policy,
    install_accepted_links,
    jsonargparse_problems,
    private_api_problems,
)
from tests.helpers.cli_builds import build_cli

CHECKED = (
    f"lightning {pl.__version__} and jsonargparse {jsonargparse.__version__} installed; "
    f"tasks/training/lightning_compat.py was checked against lightning {CHECKED_LIGHTNING[0]} to "
    f"{CHECKED_LIGHTNING[1]} and jsonargparse {', '.join(CHECKED_JSONARGPARSE)}"
)


def test_the_private_names_the_adapter_uses_are_there():
    import importlib

    for name in PRIVATE_NAMES:
        module_name, attr = name.rsplit(".", 1)
        assert hasattr(importlib.import_module(module_name), attr), f"{name} is gone ({CHECKED})"
    assert private_api_problems() == [], f"{private_api_problems()} ({CHECKED})"
    assert hasattr(pl.cli.LightningArgumentParser, "add_instantiator"), (
        f"jsonargparse removed ArgumentParser.add_instantiator ({CHECKED})"
    )


class _Outside(pl.Callback):
    """A callback of this test module: outside any allow-list but the test's own."""


def test_the_jsonargparse_import_policy_refuses_before_import_and_is_restored(tmp_path, monkeypatch):
    assert jsonargparse_problems() == [], f"{jsonargparse_problems()} ({CHECKED})"
    marker = tmp_path / "IMPORTED"
    (tmp_path / "compat_policy_probe.py").write_text(
        f"open({str(marker)!r}, 'w').close()\n"
        "from lightning.pytorch import Callback\nclass C(Callback): pass\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    parser = jsonargparse.ArgumentParser(exit_on_error=False)
    parser.add_subclass_arguments(pl.Callback, "cb")
    with import_policy(["lightning.pytorch"]):
        for path in ("compat_policy_probe.C", f"{__name__}._Outside", "os.system"):
            with pytest.raises(jsonargparse.ArgumentError, match="not allowed"):
                parser.parse_args([f"--cb={path}"])
        assert not marker.exists(), f"the policy let an import through ({CHECKED})"
        assert parser.parse_args(["--cb=lightning.pytorch.callbacks.ModelCheckpoint"]).cb.class_path
    with import_policy(["lightning.pytorch", "compat_policy_probe"]):
        assert parser.parse_args(["--cb=compat_policy_probe.C"]).cb.class_path == "compat_policy_probe.C"
    assert marker.exists()
    assert (
        parser.parse_args([f"--cb={__name__}._Outside"]).cb.class_path == f"{__name__}._Outside"
    )  # restored


def test_a_changed_instantiator_is_reported(monkeypatch):
    """The import-time check of the adapter reads the signature it needs (here: a changed constructor)."""

    def changed_init(self, cli, key, extra):
        pass

    monkeypatch.setattr(lightning_compat._InstantiatorFn, "__init__", changed_init)
    assert private_api_problems() == ["_InstantiatorFn(cli, key) changed its constructor"]


# --- the behaviour the adapter exists for ---------------------------------------------------------


class Data(LightningDataModule):
    """A data module whose ``batch_size`` and ``seed_frames`` are linked to the model."""

    def __init__(self, batch_size: int = 6, seed_frames: int = 12) -> None:
        super().__init__()
        self.batch_size, self.seed_frames = batch_size, seed_frames


class WithoutLinkedArguments(LightningModule):
    """A model with neither ``batch_size`` nor ``network`` (the links' targets)."""

    def __init__(self, lr: float = 0.1) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.layer = torch.nn.Linear(1, 1)


class WithLinkedArguments(LightningModule):
    """A model taking ``batch_size`` and a ``network`` dict with ``seed_frames``."""

    def __init__(self, batch_size: int = 1, network: dict | None = None, lr: float = 0.1) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.layer = torch.nn.Linear(1, 1)


class LinkingCLI(LightningCLI):
    """Two instantiation links, as ``sm`` links data-module values to the model."""

    filter_links = True
    nested = True

    def add_arguments_to_parser(self, parser) -> None:
        parser.link_arguments("data.batch_size", "model.init_args.batch_size", apply_on="instantiate")
        if self.nested:
            parser.link_arguments(
                "data.seed_frames", "model.init_args.network.seed_frames", apply_on="instantiate"
            )

    def before_instantiate_classes(self) -> None:
        if self.filter_links:
            install_accepted_links(self)


def build(model: type, cli_class: type = LinkingCLI, model_args: tuple[str, ...] = ()) -> LightningModule:
    args = [f"--model={__name__}.{model.__name__}", *model_args, f"--data={__name__}.Data"]
    args += ["--trainer.logger=false", "--trainer.enable_checkpointing=false"]
    return build_cli(cli_class, args).model


@pytest.fixture(autouse=True)
def _cli_argv(monkeypatch):
    monkeypatch.setattr(sys, "argv", ["sm"])  # the arguments are passed as args=


def test_plain_lightning_stores_links_the_model_has_no_argument_for():
    """Why the adapter exists: without it the checkpoint's hyper-parameters name an argument the model
    lacks. When this fails, Lightning stopped doing so and ``AcceptedLinksInstantiator`` may go."""

    class PlainCLI(LinkingCLI):
        filter_links = False
        nested = False

    class PlainNestedCLI(PlainCLI):
        nested = True

    hparams = build(WithoutLinkedArguments, PlainCLI).hparams
    assert hparams.get("batch_size") == 6, f"Lightning no longer stores unaccepted links ({CHECKED})"
    with pytest.raises(ValueError, match="network.seed_frames"):  # a nested link fails at instantiation
        build(WithoutLinkedArguments, PlainNestedCLI)


def test_the_filter_drops_the_links_the_model_lacks_and_keeps_the_others():
    without = build(WithoutLinkedArguments).hparams
    assert "batch_size" not in without and "network" not in without, (
        f"the accepted-links instantiator did not take effect: LightningCLI may now register its own after "
        f"before_instantiate_classes ({CHECKED})"
    )
    assert without["lr"] == 0.1
    model = build(WithLinkedArguments, model_args=("--model.init_args.network={}",))
    assert model.hparams["batch_size"] == 6 and model.hparams["network"] == {"seed_frames": 12}


# --- attached_trainer: LightningModule's trainer, or None -----------------------------------------


def test_attached_trainer_is_the_trainer_or_none():
    module = WithoutLinkedArguments()
    with pytest.raises(RuntimeError, match="not attached"):  # what attached_trainer turns into None
        _ = module.trainer
    assert attached_trainer(module) is None
    trainer = pl.Trainer(accelerator="cpu", logger=False, enable_checkpointing=False)
    module.trainer = trainer
    assert attached_trainer(module) is trainer
    module.trainer = None
    assert attached_trainer(module) is None


def test_attached_trainer_is_none_under_fabric():
    from lightning.fabric import Fabric

    module = WithoutLinkedArguments()
    module.fabric = Fabric(accelerator="cpu", devices=1)
    assert attached_trainer(module) is None  # module.trainer is Lightning's Fabric stand-in here
