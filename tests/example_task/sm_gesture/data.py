"""Generated gesture data: 2-D keypoints on a skeleton, each class a different oscillation of the joints."""

from __future__ import annotations

import dataclasses

import torch
from torch.utils.data import TensorDataset

from skeleton_mamba import get_skeleton
from skeleton_mamba.tasks.training.base_data import DataContract, SplitDataModule


@dataclasses.dataclass(frozen=True, kw_only=True)
class GestureContract(DataContract):
    """What the keypoints fix for the model: linked to its arguments of the same names."""

    num_classes: int
    skeleton: str


class GestureDataModule(SplitDataModule):
    """Keypoints (T, J, 2) of ``num_classes`` generated gestures, ``per_class`` samples each per split.

    ``num_classes`` and ``skeleton`` follow from the data (:class:`GestureContract`): LightningCLI links
    them to the module's arguments of those names.
    """

    contract_class = GestureContract

    def __init__(
        self,
        num_classes: int = 4,
        per_class: int = 8,
        frames: int = 16,
        skeleton: str = "openpose18",
        seed: int = 0,
        batch_size: int = 8,
        num_workers: int = 0,
    ) -> None:
        super().__init__(batch_size, num_workers)
        self.num_classes = num_classes
        self.skeleton = skeleton
        self.per_class, self.frames, self.seed = per_class, frames, seed

    @property
    def contract(self) -> GestureContract:
        return GestureContract(num_classes=self.num_classes, skeleton=self.skeleton)

    def _split(self, generator: torch.Generator) -> TensorDataset:
        joints = get_skeleton(self.skeleton).num_joints
        label = torch.arange(self.num_classes).repeat_interleave(self.per_class)
        t = torch.linspace(0, 1, self.frames)[None, :, None, None]
        phase = torch.rand(len(label), 1, joints, 1, generator=generator)
        wave = torch.sin(2 * torch.pi * (label[:, None, None, None] + 1) * (t + phase))
        noise = 0.1 * torch.randn(len(label), self.frames, joints, 2, generator=generator)
        return TensorDataset(wave.expand(-1, -1, -1, 2) + noise, label)

    def setup(self, stage: str) -> None:
        generator = torch.Generator().manual_seed(self.seed)
        self.datasets = {split: self._split(generator) for split in ("train", "val", "test")}
