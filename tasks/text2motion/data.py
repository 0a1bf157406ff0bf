"""Text-to-motion data: captioned clips as normalised (T, 263) features, variable-length batches.

A sample is ``{"motion": (L, 263) float32 normalised, "caption": str, "length": L}``: a random caption
of the clip, a random crop of a length that is a multiple of 4 (:func:`crop_length`, at most 196), and
``(x - Mean) / Std``. :func:`collate_text_motion` pads a batch to its longest sample with zeros and a
frame mask (B, T) (True = valid), which the backbone uses for variable lengths.

Data modules: :class:`HumanML3DDataModule` (the real dataset, read by :mod:`.humanml3d`) and
:class:`SyntheticTextMotionDataModule` (SYNTHETIC captioned dances, :mod:`.synthetic`, no download).
Both expose ``statistics()`` (Mean, Std), which the task module stores to de-normalise generations.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from skeleton_mamba.errors import DatasetNotFoundError
from skeleton_mamba.tasks.motion.formats.humanml3d_features import group_statistics, read_statistics
from skeleton_mamba.tasks.text2motion.humanml3d import UNIT_LENGTH, MotionClip, crop_length, load_clips
from skeleton_mamba.tasks.text2motion.synthetic import KINDS, check_kinds, synthetic_clips
from skeleton_mamba.tasks.training.base_data import DataContract, SplitDataModule, unlinked

__all__ = [
    "TextMotionContract",
    "TextMotionDataset",
    "TextMotionStatistics",
    "collate_text_motion",
    "HumanML3DDataModule",
    "SyntheticTextMotionDataModule",
    "STATISTICS_FRAMES",
]

STATISTICS_FRAMES = 200_000  # frames of training features for the preconditioning statistics


class TextMotionDataset(Dataset):
    """Random caption and crop of each clip, normalised with ``mean`` / ``std`` (263,)."""

    def __init__(
        self, clips: list[MotionClip], mean: np.ndarray, std: np.ndarray, unit_length: int = UNIT_LENGTH
    ) -> None:
        self.clips = clips
        self.mean = mean.astype(np.float32)
        self.std = std.astype(np.float32)
        self.unit_length = unit_length

    def __len__(self) -> int:
        return len(self.clips)

    def __getitem__(self, index: int) -> dict:
        # torch's RNG is seeded per worker by Lightning, so workers draw different crops
        rng = np.random.default_rng(int(torch.randint(2**31 - 1, ())))
        clip = self.clips[index]
        caption = clip.captions[int(rng.integers(len(clip.captions)))]
        length = crop_length(clip.length, rng, self.unit_length)
        start = int(rng.integers(clip.length - length + 1))
        motion = (clip.features[start : start + length] - self.mean) / self.std
        motion = torch.from_numpy(motion.astype(np.float32))
        return {"motion": motion, "caption": caption.text, "length": length, "sample_id": clip.motion_id}


def collate_text_motion(items: list[dict]) -> dict:
    """Pad to the longest: motion (B, T, 263), mask (B, T) bool, length (B,), caption and sample_id lists."""
    lengths = torch.tensor([item["length"] for item in items])
    motion = torch.zeros(len(items), int(lengths.max()), items[0]["motion"].shape[-1])
    for i, item in enumerate(items):
        motion[i, : item["length"]] = item["motion"]
    mask = torch.arange(motion.shape[1])[None] < lengths[:, None]
    return {
        "motion": motion,
        "mask": mask,
        "length": lengths,
        "caption": [item["caption"] for item in items],
        "sample_id": [item.get("sample_id", "") for item in items],
    }


@dataclasses.dataclass(frozen=True)
class TextMotionStatistics:
    """``feature_mean`` and ``feature_std`` (263,) of the normalisation and, once the training split is set
    up, ``features`` (N, 263): its first :data:`STATISTICS_FRAMES` frames, normalised, and
    ``feature_lengths`` (K,) the frames each clip gives them (the denoiser's preconditioning statistics; its
    temporal prior's spectrum is measured within clips)."""

    feature_mean: torch.Tensor
    feature_std: torch.Tensor
    features: torch.Tensor | None = None
    feature_lengths: torch.Tensor | None = None


@dataclasses.dataclass(frozen=True, kw_only=True)
class TextMotionContract(DataContract):
    """What the clips fix for the text-to-motion module: no size (the 263-d representation is the model's
    own), only the normalisation and training features (:class:`TextMotionStatistics`)."""

    statistics: TextMotionStatistics | None = unlinked(None)


class _TextMotionDataModule(SplitDataModule):
    contract_class = TextMotionContract

    @property
    def contract(self) -> TextMotionContract:
        """What the data fixes for the model (:class:`TextMotionContract`)."""
        return TextMotionContract()

    def statistics(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(Mean, Std) (263,) float32 used for normalisation."""
        mean, std = self._statistics()
        return torch.from_numpy(mean.astype(np.float32)), torch.from_numpy(std.astype(np.float32))

    def _statistics(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def training_statistics(self) -> TextMotionStatistics:
        """The normalisation and, once the training split is set up, its features
        (:class:`TextMotionStatistics`)."""
        mean, std = self.statistics()
        train = self.datasets.get("train")
        if train is None or len(train) == 0:
            return TextMotionStatistics(feature_mean=mean, feature_std=std)
        frames = np.concatenate([clip.features for clip in train.clips])[:STATISTICS_FRAMES]
        features = (torch.from_numpy(frames.astype(np.float32)) - mean.float()) / std.float()
        ends = np.cumsum([clip.length for clip in train.clips]).clip(max=len(frames))
        lengths = torch.from_numpy(np.diff(ends, prepend=0)).long()
        return TextMotionStatistics(
            feature_mean=mean, feature_std=std, features=features, feature_lengths=lengths
        )

    def evaluation_clips(self, split: str = "test") -> list[MotionClip]:
        """The clips of a set-up split (the T2M evaluation draws its own captions and crops)."""
        if split not in self.datasets:
            raise RuntimeError(f"{type(self).__name__}: split {split!r} is not set up (call setup first)")
        return self.datasets[split].clips

    def loader_options(self, split: str) -> dict:
        return {"collate_fn": collate_text_motion}


class HumanML3DDataModule(_TextMotionDataModule):
    """HumanML3D train / val / test splits.

    Args:
        root: folder with ``new_joint_vecs/``, ``texts/``, ``Mean.npy``, ``Std.npy`` and the split lists.
        batch_size: per-device batch (MDM: 64).
        num_workers: data loader workers.
        limit: read at most this many ids per split (quick runs).
    """

    def __init__(
        self,
        root: str = "data/humanml3d",
        batch_size: int = 64,
        num_workers: int = 4,
        limit: int | None = None,
    ) -> None:
        super().__init__(batch_size, num_workers)
        self.root = Path(root)
        self.limit = limit

    def _check(self) -> None:
        if not (self.root / "new_joint_vecs").is_dir() or not (self.root / "texts").is_dir():
            raise DatasetNotFoundError(
                f"HumanML3D not found at {self.root}: build it with the scripts of "
                "github.com/EricGuo5513/HumanML3D (needs AMASS) and set data.root to the folder holding "
                "new_joint_vecs/, texts/, Mean.npy, Std.npy and train/val/test.txt"
            )

    def _statistics(self) -> tuple[np.ndarray, np.ndarray]:
        return read_statistics(self.root)

    def setup(self, stage: str) -> None:
        self._check()
        mean, std = self._statistics()
        splits = {"fit": ("train", "val"), "validate": ("val",), "test": ("test",), "predict": ("test",)}
        for split in splits.get(stage, ()):
            if split not in self.datasets:
                clips = load_clips(self.root, split, limit=self.limit)
                self.datasets[split] = TextMotionDataset(clips, mean, std)


class SyntheticTextMotionDataModule(_TextMotionDataModule):
    """SYNTHETIC captioned dances (:mod:`.synthetic`); statistics computed from the training clips.

    Args:
        train_clips: number of training clips.
        val_clips: number of validation (and test) clips.
        min_frames: shortest clip.
        max_frames: longest clip (196 as HumanML3D).
        seed: generator seed (validation uses ``seed + 1``).
        batch_size: per-device batch.
        num_workers: data loader workers.
        kinds: the clips' kinds, in turn: dance styles (``bounce``, ``sway``, ``arms``, the default) or
            everyday actions (``walk``, ``turn``, ``jump``, ``squat``, ``kick``, ``wave``, ``run_in_place``).
    """

    def __init__(
        self,
        train_clips: int = 48,
        val_clips: int = 12,
        min_frames: int = 40,
        max_frames: int = 196,
        seed: int = 0,
        batch_size: int = 16,
        num_workers: int = 0,
        kinds: list[str] | None = None,
    ) -> None:
        super().__init__(batch_size, num_workers)
        self.kinds = tuple(kinds) if kinds else KINDS
        check_kinds(self.kinds)  # unknown kinds refused when the module is made
        self.train_clips, self.val_clips = train_clips, val_clips
        self.min_frames, self.max_frames, self.seed = min_frames, max_frames, seed
        self._clips: dict[str, list[MotionClip]] = {}

    def _clips_of(self, split: str) -> list[MotionClip]:
        if split not in self._clips:
            train = split == "train"
            count, seed = (self.train_clips, self.seed) if train else (self.val_clips, self.seed + 1)
            self._clips[split] = synthetic_clips(count, seed, self.min_frames, self.max_frames, self.kinds)
        return self._clips[split]

    def _statistics(self) -> tuple[np.ndarray, np.ndarray]:
        frames = torch.from_numpy(np.concatenate([c.features for c in self._clips_of("train")]))
        mean, std = group_statistics(frames.double())
        return mean.numpy(), std.clamp(min=1e-3).numpy()

    def setup(self, stage: str) -> None:
        mean, std = self._statistics()
        for split in ("train", "val", "test"):
            source = "train" if split == "train" else "val"
            self.datasets.setdefault(split, TextMotionDataset(self._clips_of(source), mean, std))
