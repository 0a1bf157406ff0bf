"""A data module whose training samples are a malformed file, read in DataLoader worker processes (for
tests/training/test_error_format.py: ``sm fit --data.num_workers 1`` must still print one line naming the
file)."""

from __future__ import annotations

from torch.utils.data import DataLoader, Dataset

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.tasks.recognition.data import SyntheticRecognitionDataModule


class _MalformedFile(Dataset):
    def __init__(self, path: str) -> None:
        self.path = path

    def __len__(self) -> int:
        return 8

    def __getitem__(self, index: int):
        raise DataFileError(f"{self.path}: frame {index}: NaN in the joint positions")


class MalformedTrainingFileDataModule(SyntheticRecognitionDataModule):
    """The generated validation split; training samples that all raise :class:`DataFileError`.

    Args:
        bad_file: the path the training samples' error names.
        num_workers: DataLoader worker processes.
    """

    def __init__(self, bad_file: str = "sample.npy", num_workers: int = 0) -> None:
        super().__init__(num_workers=num_workers)
        self.bad_file = bad_file

    def train_dataloader(self) -> DataLoader:
        return DataLoader(_MalformedFile(self.bad_file), batch_size=2, num_workers=self.num_workers)
