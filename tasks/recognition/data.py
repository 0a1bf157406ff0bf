"""LightningDataModule for skeleton action recognition on PYSKL annotation files.

One pickle (``sm prepare ntu60|ntu120|kinetics`` writes it; PYSKL's ``ntu60_3danno.pkl`` works as is)
holds every sample and the named splits; the data module picks ``train_split`` / ``val_split`` /
``test_split`` and runs :class:`.transforms.SkeletonPipeline` per sample:

- training: 1 random clip of ``clip_len`` frames, optional PYSKL ``RandomScale`` / ``RandomRot`` (by
  default on the whole sequence before sampling, as PYSKL's configs order them);
- validation: ``num_clips_val`` deterministic clips; test: ``num_clips_test`` (PYSKL: 10, seed 255);
- every stage: the [PYSKL] ``GenSkeFeat`` features ``feats`` (``[j]`` joints by default; ``[b]`` bones,
  ``[jm]`` joint motion, ``[bm]`` bone motion, or several concatenated, ``[j, b, jm, bm]``), computed on the
  whole sequence before sampling (:func:`.transforms.skeleton_features`). One model per stream and
  ``sm ensemble`` over their ``sm test`` scores is PYSKL's multi-stream protocol.

A batch is ``(keypoint (B, N, M, T, V, C) float32, label (B,) int64)`` with N clips and M bodies.

The keypoints are read from a memory-mapped copy of the annotation file (:mod:`.keypoint_store`, built once
per machine by Lightning's ``prepare_data`` on the node's first rank): every rank and loader worker maps the
same pages, so the data set is held once per machine whatever the number of ranks. Under DDP the validation
and test splits are divided among the ranks without the padding samples of torch's ``DistributedSampler``,
so the accuracy of N processes is the accuracy of one over the same split.

``num_classes``, ``skeleton``, ``in_channels`` and ``batch_size`` are its :class:`RecognitionContract`, which
``sm`` links to the model's arguments of those names (``in_channels`` is read off the pipeline output: x y z
for 3D, x y score for 2D, times the number of ``feats``). ``batch_size`` is the per-device batch; the model
scales its learning rate by the global batch.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np
import torch
from lightning.pytorch.overrides.distributed import UnrepeatedDistributedSampler
from torch.utils.data import Dataset

from skeleton_mamba.errors import DataFileError, DatasetNotFoundError, InputError
from skeleton_mamba.skeletons import get_skeleton
from skeleton_mamba.tasks.recognition.keypoint_store import KeypointStore, StoreSplit, ensure_store
from skeleton_mamba.tasks.recognition.pyskl import load_annotations
from skeleton_mamba.tasks.recognition.synthetic import make_synthetic_annotations
from skeleton_mamba.tasks.recognition.transforms import SkeletonPipeline, check_features
from skeleton_mamba.tasks.training.base_data import DataContract, SplitDataModule

__all__ = ["Feature", "RecognitionDataModule", "SkeletonClipDataset", "SyntheticRecognitionDataModule"]

Feature = Literal["j", "b", "jm", "bm"]
"""A [PYSKL] ``GenSkeFeat`` feature: joint, bone, joint motion, bone motion (:data:`.transforms.FEATURES`)."""


class SkeletonClipDataset(Dataset):
    """Annotations -> ``(clips (N, M, T, V, C) float32 tensor, label)`` through a pipeline.

    Training randomness comes from torch's generator (seeded per worker by the DataLoader and by
    ``seed_everything(workers=True)``), so runs are reproducible and workers differ.
    """

    def __init__(self, annotations: Sequence[dict], pipeline: SkeletonPipeline) -> None:
        self.annotations = annotations
        self.pipeline = pipeline

    def __len__(self) -> int:
        return len(self.annotations)

    @property
    def sample_names(self) -> list[str]:
        """Each sample's ``frame_dir``, in order (read from the index, not the keypoints, for a store)."""
        if isinstance(self.annotations, StoreSplit):
            return self.annotations.sample_names
        return [a["frame_dir"] for a in self.annotations]

    def __getitem__(self, index: int) -> tuple[torch.Tensor, int]:
        annotation = self.annotations[index]
        rng = None if self.pipeline.test_mode else np.random.default_rng(int(torch.randint(2**62, ()).item()))
        return torch.from_numpy(self.pipeline(annotation, rng)), annotation["label"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class RecognitionContract(DataContract):
    """What the clips fix for the recognizer: K classes, the skeleton, channels per joint and the per-device
    batch (the learning rate's scaling)."""

    num_classes: int
    skeleton: str
    in_channels: int
    batch_size: int


class RecognitionDataModule(SplitDataModule):
    """Skeleton clips from a PYSKL annotation pickle.

    Args:
        ann_file: the annotation pickle.
        num_classes: classes of the data set (NTU60 60, NTU120 120, Kinetics 400).
        skeleton: joint layout of the keypoints (``ntu25`` or ``openpose18``).
        feats: the input stream: PYSKL ``GenSkeFeat`` features, concatenated on the channel axis in this
            order: ``[j]`` joints, ``[b]`` bones (each joint minus its PYSKL pair), ``[jm]`` / ``[bm]`` joint
            / bone motion (next frame minus this one, zero at the last), or several (``[j, b, jm, bm]``);
            ``in_channels`` follows. On the command line: ``--data.init_args.feats '[b]'``.
        train_split: split name for training (PYSKL names, e.g. ``xsub_train``).
        val_split: split name for validation.
        test_split: split name for testing (``None``: the validation split, as PYSKL does).
        clip_len: frames per clip (PYSKL GCN configs: 100).
        num_clips_val: clips per validation sample.
        num_clips_test: clips per test sample; their softmax scores are averaged (PYSKL: 10).
        num_person: bodies per sample (zero-padded).
        max_angle: training ``RandomRot`` range in radians (0: off, as PYSKL's ST-GCN++ configs; its
            strong-augmentation configs use 0.3).
        scale_range: training ``RandomScale`` per-axis range (0: off; strong augmentation: 0.1).
        augment_before_sampling: scale / rotate the whole sequence, then sample frames (PYSKL's order);
            False samples first (see :class:`.transforms.SkeletonPipeline`).
        batch_size: per-device batch size.
        num_workers: DataLoader worker processes.
        prepare_command: how to build ``ann_file`` (shown when it is missing).
        memory_map: read the keypoints from a memory-mapped copy of ``ann_file``, one per machine
            (:mod:`.keypoint_store`); False unpickles the whole file in every process.
        store_dir: where the memory-mapped copies go (default ``~/.cache/skeleton_mamba/keypoints``, or
            ``$SKELETON_MAMBA_CACHE/keypoints``): a local disk of each node.
    """

    def __init__(
        self,
        ann_file: str,
        num_classes: int,
        skeleton: str = "ntu25",
        feats: Sequence[Feature] = ("j",),
        train_split: str = "xsub_train",
        val_split: str = "xsub_val",
        test_split: str | None = None,
        clip_len: int = 100,
        num_clips_val: int = 1,
        num_clips_test: int = 10,
        num_person: int = 2,
        max_angle: float = 0.0,
        scale_range: float = 0.0,
        augment_before_sampling: bool = True,
        batch_size: int = 128,
        num_workers: int = 4,
        prepare_command: str | None = None,
        memory_map: bool = True,
        store_dir: str | None = None,
    ) -> None:
        super().__init__(batch_size, num_workers)
        self.save_hyperparameters()
        get_skeleton(skeleton)  # fail early on an unknown name
        try:
            self.feats = check_features(feats, skeleton)
        except ValueError as err:
            raise InputError(f"data feats: {err}") from None
        self.ann_file = ann_file
        self.num_classes = num_classes
        self.skeleton = skeleton
        self.splits = {"train": train_split, "val": val_split, "test": test_split or val_split}
        self.clip_len = clip_len
        self.num_clips = {"validate": num_clips_val, "test": num_clips_test}
        self.num_person = num_person
        self.max_angle = max_angle
        self.scale_range = scale_range
        self.augment_before_sampling = augment_before_sampling
        self.prepare_command = prepare_command
        self.memory_map = memory_map
        self.store_dir = store_dir
        self._data: dict | KeypointStore | None = None
        self.check_data()

    def check_data(self) -> None:
        """Raise :class:`DatasetNotFoundError` (where the data goes, how to build it) without ``ann_file``."""
        path = Path(self.ann_file).expanduser()
        if path.is_file():
            return
        how = f"Build it with:\n    {self.prepare_command}\n" if self.prepare_command else ""
        raise DatasetNotFoundError(
            f"annotation file not found: {path.resolve()}\n{how}"
            f"Or point the recipe at it with --data.init_args.ann_file PATH."
        )

    def prepare_data(self) -> None:
        """Build the memory-mapped copy of ``ann_file`` once per node (Lightning calls this on each node's
        first rank before the others set up)."""
        if self.memory_map:
            ensure_store(self.ann_file, self.store_dir)

    def load(self) -> dict | KeypointStore:
        """The samples and splits: the memory-mapped store (built first when missing), or the PYSKL
        annotation dict unpickled whole (``memory_map=False``); read once, validated."""
        if self._data is None:
            self._data = (
                ensure_store(self.ann_file, self.store_dir)
                if self.memory_map
                else load_annotations(self.ann_file)
            )
        return self._data

    def _split(self, name: str) -> Sequence[dict]:
        data = self.load()
        splits = data.splits if isinstance(data, KeypointStore) else data["split"]
        if name not in splits:
            raise DataFileError(f"{self.ann_file}: no split {name!r}; it has {sorted(splits)}")
        if not len(splits[name]):
            raise DataFileError(f"{self.ann_file}: split {name!r} is empty")
        if isinstance(data, KeypointStore):
            annotations: Sequence[dict] = data.split(name)
            labels, names, joints = annotations.labels, annotations.sample_names, {data.num_joints}
        else:
            by_name = {a["frame_dir"]: a for a in data["annotations"]}
            annotations = [by_name[n] for n in data["split"][name]]
            labels = np.asarray([a["label"] for a in annotations])
            names, joints = data["split"][name], {a["keypoint"].shape[2] for a in annotations}
        outside = (labels < 0) | (labels >= self.num_classes)
        if outside.any():
            bad = [names[i] for i in np.flatnonzero(outside)[:3]]
            raise DataFileError(f"{self.ann_file}: labels outside [0, {self.num_classes}) in {bad}")
        found = sorted(joints - {get_skeleton(self.skeleton).num_joints})
        if found:
            raise DataFileError(
                f"{self.ann_file}: split {name!r} has samples with {found} joints; "
                f"skeleton {self.skeleton!r} has {get_skeleton(self.skeleton).num_joints}"
            )
        return annotations

    def pipeline(self, stage: str) -> SkeletonPipeline:
        """The sample pipeline of ``fit`` (training), ``validate`` or ``test``/``predict``."""
        if stage == "fit":
            return SkeletonPipeline(
                self.clip_len,
                1,
                False,
                self.num_person,
                self.max_angle,
                self.scale_range,
                augment_before_sampling=self.augment_before_sampling,
                feats=self.feats,
                skeleton=self.skeleton,
            )
        num_clips = self.num_clips["validate" if stage == "validate" else "test"]
        return SkeletonPipeline(
            self.clip_len, num_clips, True, self.num_person, feats=self.feats, skeleton=self.skeleton
        )

    contract_class = RecognitionContract

    @property
    def contract(self) -> RecognitionContract:
        """What the data fixes for the model (:class:`RecognitionContract`)."""
        return RecognitionContract(
            num_classes=self.num_classes,
            skeleton=self.skeleton,
            in_channels=self.in_channels,
            batch_size=self.batch_size,
        )

    @property
    def in_channels(self) -> int:
        """Per-joint channels C of the network input (from the first training sample)."""
        data = self.load()
        if isinstance(data, KeypointStore):
            first = data.annotation(0)
        else:
            train = data["split"].get(self.splits["train"])
            if not data["annotations"]:
                raise DataFileError(f"{self.ann_file}: no annotations")
            first = self._split(self.splits["train"])[0] if train else data["annotations"][0]
        return int(self.pipeline("validate")(first).shape[-1])

    def setup(self, stage: str) -> None:
        keys = {"fit": ("train", "val"), "validate": ("val",)}.get(stage, ("test",))
        for key in keys:
            if key not in self.datasets:
                pipeline = self.pipeline({"train": "fit", "val": "validate"}.get(key, "test"))
                self.datasets[key] = SkeletonClipDataset(self._split(self.splits[key]), pipeline)

    def loader_options(self, split: str) -> dict:
        options = {
            "drop_last": split == "train",
            "persistent_workers": self.num_workers > 0,
            "pin_memory": torch.cuda.is_available(),
        }
        trainer = self.trainer
        if split != "train" and trainer is not None and trainer.world_size > 1:
            # each rank its share of the split, no sample repeated to even them (Lightning keeps this sampler)
            sampler = UnrepeatedDistributedSampler(
                self.datasets[split], num_replicas=trainer.world_size, rank=trainer.global_rank, shuffle=False
            )
            options.update(sampler=sampler, shuffle=False)
        return options


class SyntheticRecognitionDataModule(RecognitionDataModule):
    """Generated class-separable sequences (:func:`.synthetic.make_synthetic_annotations`); no files.

    Args:
        num_classes: K classes.
        train_per_class: training samples per class.
        val_per_class: validation (and test) samples per class.
        num_frames: frames per generated sequence.
        skeleton: ``ntu25`` (3D) or ``openpose18`` (2D with scores).
        feats: the input stream (PYSKL ``GenSkeFeat`` features; see :class:`RecognitionDataModule`).
        num_bodies: bodies per generated sequence.
        seed: generator seed.
        clip_len: frames per clip.
        num_clips_test: test clips per sample.
        num_person: bodies per network input.
        batch_size: per-device batch size.
        num_workers: DataLoader worker processes.
    """

    def __init__(
        self,
        num_classes: int = 3,
        train_per_class: int = 16,
        val_per_class: int = 8,
        num_frames: int = 32,
        skeleton: str = "ntu25",
        feats: Sequence[Feature] = ("j",),
        num_bodies: int = 1,
        seed: int = 0,
        clip_len: int = 16,
        num_clips_test: int = 2,
        num_person: int = 1,
        batch_size: int = 8,
        num_workers: int = 0,
    ) -> None:
        super().__init__(
            ann_file="<generated>",
            num_classes=num_classes,
            skeleton=skeleton,
            feats=feats,
            clip_len=clip_len,
            num_clips_test=num_clips_test,
            num_person=num_person,
            batch_size=batch_size,
            num_workers=num_workers,
            memory_map=False,
        )
        self.save_hyperparameters()
        self.generator_args = dict(
            num_classes=num_classes, train_per_class=train_per_class, val_per_class=val_per_class,
            num_frames=num_frames, skeleton=skeleton, num_bodies=num_bodies, seed=seed,
        )  # fmt: skip

    def check_data(self) -> None:
        """Nothing to check: the data is generated."""

    def load(self) -> dict:
        if self._data is None:
            self._data = make_synthetic_annotations(**self.generator_args)
        return self._data
