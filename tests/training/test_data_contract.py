"""The data-to-model contract (issue 28): what follows from the data is declared once, by the data module.

Sizes and rates reach the model through LightningCLI's links from the data module's attributes, the
training statistics through ``BackboneModule.setup``; both are read from the data module's
:class:`DataContract`, so a data module with another music width or other training music changes the model
without any recipe saying so.
"""

from __future__ import annotations

import dataclasses

import lightning.pytorch as pl
import pytest
import torch
from lightning.pytorch import LightningDataModule, LightningModule

from skeleton_mamba.errors import InputError, expected_failure, one_line_message
from skeleton_mamba.tasks.qean.data import QEANContract
from skeleton_mamba.tasks.qean.model import QEANConfig
from skeleton_mamba.tasks.qean.module import QEANModule
from skeleton_mamba.tasks.recognition.data import SyntheticRecognitionDataModule
from skeleton_mamba.tasks.stream.data import StreamContract, StreamDanceDataModule
from skeleton_mamba.tasks.stream.module import StreamDanceModule
from skeleton_mamba.tasks.text2motion.data import SyntheticTextMotionDataModule
from skeleton_mamba.tasks.training.base_data import DataContract, SplitDataModule, data_contract, unlinked
from skeleton_mamba.tasks.training.base_module import BackboneModule
from skeleton_mamba.tasks.training.lightning_cli import SkeletonMambaCLI, import_task_modules

TINY = {"dim": 16, "depth": 1, "heads": 2, "mlp_dim": 32, "group_paths": [[1, 2, 0, 3, 4]],
        "mixer": {"d_state": 16, "headdim": 8, "chunk_size": 16}}  # fmt: skip


class NarrowMusic(StreamDanceDataModule):
    """The streaming dancer's data with 20 music features per frame (the first 20 of the causal 34)."""

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self.music_dim = 20

    def sequence(self, name: str):
        motion, music = super().sequence(name)
        return motion, music[:, : self.music_dim]


def test_every_task_data_module_exposes_the_typed_contract(tmp_path):
    recognition = SyntheticRecognitionDataModule(num_classes=3, train_per_class=2, val_per_class=1)
    assert isinstance(recognition, SplitDataModule)
    contract = recognition.contract
    assert isinstance(contract, DataContract)
    assert (contract.num_classes, contract.skeleton) == (3, recognition.skeleton)
    assert contract.statistics is None  # recognition has no data-dependent normalisation
    stream = StreamDanceDataModule(root=str(tmp_path), synthetic=True, synthetic_count=2, window_frames=30)
    assert data_contract(stream).music_dim == 34 and data_contract(stream).statistics is None  # before setup
    with pytest.raises(dataclasses.FrozenInstanceError):
        contract.music_dim = 3  # type: ignore[misc]


def test_text_statistics_are_the_normalised_training_features():
    data = SyntheticTextMotionDataModule(train_clips=4, val_clips=2, batch_size=2)
    data.setup("fit")
    statistics = data_contract(data).statistics
    mean, std = data.statistics()
    clips = data.evaluation_clips("train")
    truth = torch.cat([torch.as_tensor(c.features, dtype=torch.float64) for c in clips])
    truth = (truth - mean.double()) / std.double()
    torch.testing.assert_close(statistics.features.double(), truth, rtol=1e-6, atol=1e-6)
    assert torch.equal(statistics.feature_mean, mean) and torch.equal(statistics.feature_std, std)


def _cli(tmp_path, *args: str) -> SkeletonMambaCLI:
    import_task_modules()
    return SkeletonMambaCLI(
        LightningModule,
        LightningDataModule,
        subclass_mode_model=True,
        subclass_mode_data=True,
        run=False,
        args=[
            "--recipe", "stream_dance_demo.yaml", f"--data.init_args.root={tmp_path}",
            "--data.init_args.synthetic_count=4", "--data.init_args.synthetic_duration_s=4.0",
            "--data.init_args.window_frames=30", "--trainer.logger=false", "--trainer.callbacks=null",
            "--trainer.enable_checkpointing=false", *args,
        ],
    )  # fmt: skip


def test_music_width_flows_from_the_data_to_the_model_without_the_recipe(tmp_path):
    default = _cli(tmp_path / "a")
    assert default.model.hparams.music_dim == data_contract(default.datamodule).music_dim == 36  # beat phase
    narrow = _cli(tmp_path / "b", f"--data.class_path={__name__}.NarrowMusic")
    assert data_contract(narrow.datamodule).music_dim == 20
    assert narrow.model.hparams.music_dim == 20 and narrow.model.model.music_dim == 20
    assert narrow.model.model.music_mean.shape == (20,)


def test_training_statistics_reach_the_model_once_at_fit(tmp_path):
    data = NarrowMusic(root=str(tmp_path), synthetic=True, synthetic_count=4, synthetic_duration_s=4.0,
                       window_frames=30, batch_size=2)  # fmt: skip
    module = StreamDanceModule(backbone=TINY, music_dim=data.music_dim)
    trainer = pl.Trainer(max_steps=1, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                         enable_model_summary=False, accelerator="cpu")  # fmt: skip
    trainer.fit(module, data)
    # independent: every training music frame's mean and population standard deviation in float64
    music = torch.cat([m for _, m in data.datasets["train"].sequences.values()]).double()
    assert music.shape[1] == 20
    torch.testing.assert_close(module.model.music_mean.double(), music.mean(0), rtol=1e-5, atol=1e-5)
    std = ((music - music.mean(0)) ** 2).mean(0).sqrt().clamp_min(1e-3)
    torch.testing.assert_close(module.model.music_std.double(), std, rtol=1e-4, atol=1e-5)


class _Windows(LightningDataModule):
    """A data module fixing QEAN's window lengths, and nothing else."""

    contract_class = QEANContract

    def __init__(self, seed_frames: int) -> None:
        super().__init__()
        self.seed_frames, self.music_frames, self.predict_frames = seed_frames, 24, 4

    @property
    def contract(self) -> QEANContract:
        return QEANContract(
            music_dim=35, seed_frames=self.seed_frames, music_frames=24, predict_frames=4, generate_frames=20
        )

    def train_dataloader(self):
        return [{}]


def test_qean_checks_its_window_lengths_against_the_data_contract():
    sizes = dict(hidden=32, heads=2, motion_layers=1, audio_layers=1, cross_layers=1, mlp_dim=64, dropout=0.0)
    network = QEANConfig(**sizes, num_periods=2, seed_frames=12, music_frames=24, predict_frames=4)
    module = QEANModule(network=network)
    trainer = pl.Trainer(max_steps=1, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                         enable_model_summary=False, accelerator="cpu")  # fmt: skip
    with pytest.raises(ValueError, match=r"seed_frames = 12 but data.seed_frames = 16"):
        trainer.fit(module, _Windows(seed_frames=16))


@dataclasses.dataclass(frozen=True, kw_only=True)
class _CacheContract(DataContract):
    """A contract of a music-feature cache and a frame rate, read at run time (not linked)."""

    music_cache_dir: str = unlinked()
    fps: int = unlinked()


class _CachedMusic(SplitDataModule):
    """Test windows from a data module whose music features are cached in ``music_cache_dir``."""

    contract_class = _CacheContract

    def __init__(self, music_cache_dir: str) -> None:
        super().__init__(batch_size=1, num_workers=0)
        self.music_cache_dir, self.fps = music_cache_dir, 25

    @property
    def contract(self) -> _CacheContract:
        return _CacheContract(music_cache_dir=self.music_cache_dir, fps=self.fps)

    def setup(self, stage: str) -> None:
        self.datasets["test"] = [torch.zeros(1)]

    def training_statistics(self) -> dict[str, torch.Tensor]:
        raise AssertionError("the training statistics are read at fit only")


class _ReadsContract(BackboneModule):
    """Records the contract its test step sees."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: list[DataContract | None] = []

    def test_step(self, batch, batch_idx) -> None:
        self.seen.append(self.contract)


def test_the_test_loop_reads_the_music_cache_from_the_contract_not_the_data_hparams(tmp_path):
    module = _ReadsContract()
    assert module.contract is None  # built alone: no data module
    trainer = pl.Trainer(logger=False, enable_checkpointing=False, enable_progress_bar=False,
                         enable_model_summary=False, accelerator="cpu")  # fmt: skip
    trainer.test(module, _CachedMusic(str(tmp_path / "cache")))
    (contract,) = module.seen
    assert contract.music_cache_dir == str(tmp_path / "cache") and contract.fps == 25
    assert contract.statistics is None


@dataclasses.dataclass(frozen=True, kw_only=True)
class _MisspeltContract(DataContract):
    """The streaming contract with its music width misspelt: the dancer takes no ``music_dims``."""

    music_dims: int


class _MisspeltMusic(StreamDanceDataModule):
    contract_class = _MisspeltContract

    @property
    def contract(self) -> _MisspeltContract:
        return _MisspeltContract(music_dims=self.music_dim)


class _WrongKeyword(StreamDanceDataModule):
    """A contract built with a field name its class does not have."""

    @property
    def contract(self):
        return self.contract_class(music_dims=self.music_dim)


def test_a_contract_field_the_model_takes_nowhere_fails_at_start_in_one_line(tmp_path):
    with pytest.raises(InputError) as caught:
        _cli(tmp_path, f"--data.class_path={__name__}._MisspeltMusic")
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(
        "_MisspeltContract.music_dims (the data's) is no argument of StreamDanceModule nor a field of its "
        "config arguments"
    )
    assert not (tmp_path / "stream_dance_demo").exists()  # refused before any data was written


def test_a_contract_built_with_a_misspelt_field_fails_in_one_line(tmp_path):
    """The dataclass refuses the keyword when the link reads the contract; ``sm`` prints the cause's line."""
    with pytest.raises(ValueError) as caught:  # jsonargparse's link error, caused by ours
        _cli(tmp_path, f"--data.class_path={__name__}._WrongKeyword")
    line = one_line_message(expected_failure(caught.value))
    assert line == (
        "_WrongKeyword.contract: StreamContract.__init__() got an unexpected keyword argument 'music_dims'"
    )


class _ContractWidth(StreamDanceDataModule):
    """An attribute saying 36 music features (the recipe's, with the beat phase) and a contract saying 20."""

    @property
    def contract(self) -> StreamContract:
        return StreamContract(music_dim=20)


def test_the_links_come_from_the_contract_not_the_data_modules_attributes(tmp_path):
    cli = _cli(tmp_path, f"--data.class_path={__name__}._ContractWidth")
    assert cli.datamodule.music_dim == 36
    assert cli.link_data_contract() == [("music_dim", "music_dim")]
    assert cli.model.hparams.music_dim == 20 and cli.model.model.music_dim == 20
