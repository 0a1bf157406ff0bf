"""LightningDataModule for EgoAIST++-style data (the layout ``sm make-ego`` writes, ``builder/layout.py``).

Each complete sample folder gives one training window of ``window`` frames (150 = 5 s at 30 fps):

- ``motion`` (T, 24, 10): motion tokens (:mod:`.representation`) of the placed motion, *canonicalised*:
  the scene floor is moved to y = 0 and the root's horizontal position at frame 0 to x = z = 0 (the
  yaw is kept: the egocentric view fixes it);
- ``music`` (T, 35): the 35-d librosa features at 30 fps of the music slice in ``meta.json``;
- ``frames`` (T, 3, S, S) float in [0, 1]: the egocentric RGB frames resized to ``image_size``;
- ``head`` (T, 3): head joint targets from the camera trajectory (:func:`.guidance.head_pose_from_camera`),
  in the same canonical frame, for oracle head guidance, the head error and training the head estimator;
- ``head_rotation`` (T, 3, 3): the head joint's rotation (head-to-world) from the camera trajectory.

With ``canonicalize_init_head`` the window is also turned about the vertical so that the head faces +z in
frame 0 (the original code's ``--canonicalize_init_head``, EgoEgo's ``rotate_at_frame``): the first frame
of the egocentric video then fixes the heading, as a SLAM trajectory relative to its first frame does, so
the dance's facing direction can be learned from the video instead of being an unknowable world yaw
(:func:`initial_heading`). Long videos are stitched in the world-yaw frame, so ``sm dance`` samples
clips of at most one window from such a model.

Splits are by motion *source* so windows of one sequence never straddle splits: an AIST++ sequence in the
cross-modal test list is test; the other sources, ranked by a stable hash of their name, fill val
(``val_fraction``) then train; without AIST++ sources (the synthetic generators) ``test_fraction`` of
them go to test first (:func:`assign_splits`). The generated demo set holds out dances stratified by style
instead (:meth:`SyntheticEgoDanceDataModule.assign_splits`).
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import zlib
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from skeleton_mamba.errors import DataFileError, DatasetNotFoundError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.io.bounded_read import read_json
from skeleton_mamba.tasks.egodance.builder.build import BuildConfig, run_build
from skeleton_mamba.tasks.egodance.builder.layout import SAMPLES, complete_samples, read_frames, read_meta
from skeleton_mamba.tasks.egodance.builder.placement import yaw_matrix
from skeleton_mamba.tasks.egodance.frames import resize_frames
from skeleton_mamba.tasks.egodance.guidance import head_pose_from_camera
from skeleton_mamba.tasks.egodance.representation import FPS, encode_motion
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from skeleton_mamba.tasks.motion.commands.cli_options import progress_default
from skeleton_mamba.tasks.motion.formats import aistpp
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.io.value_checks import check_finite, load_npz
from skeleton_mamba.tasks.motion.music.features import NUM_MUSIC_FEATURES, extract_music_features
from skeleton_mamba.tasks.motion.synthetic import make_demo_set
from skeleton_mamba.tasks.motion.synthetic.splits import stratified_holdout
from skeleton_mamba.tasks.training.base_data import DataContract, SplitDataModule, unlinked

__all__ = [
    "EgoDanceContract",
    "EgoDanceDataset",
    "EgoDanceStatistics",
    "EgoDanceDataModule",
    "SyntheticEgoDanceDataModule",
    "assign_splits",
    "data_module_from_hparams",
    "initial_heading",
]

REQUIRED_FILES = ("meta.json", "motion.npz", "camera.npz")


def assign_splits(sources: list[str], val_fraction: float, test_fraction: float) -> dict[str, str]:
    """Motion source -> ``train`` | ``val`` | ``test`` (see the module docstring).

    Sources are ranked by a stable hash of their name; AIST++ cross-modal test sequences go to test,
    the first ``ceil(val_fraction * n)`` of the rest to val, and for non-AIST++ sources the first
    ``ceil(test_fraction * n)`` to test before that.
    """
    aist_test = set(aistpp.load_split("test"))
    ranked = sorted(set(sources), key=lambda s: (zlib.crc32(Path(s).stem.encode()), s))
    out: dict[str, str] = {}
    rest = []
    for src in ranked:
        stem = Path(src).stem
        if stem in aist_test:
            out[src] = "test"
        else:
            rest.append(src)
    is_aist = bool(aist_test & {Path(s).stem for s in ranked})
    n_test = 0 if is_aist else math.ceil(test_fraction * len(rest))
    n_val = math.ceil(val_fraction * len(rest))
    for i, src in enumerate(rest):
        out[src] = "test" if i < n_test else "val" if i < n_test + n_val else "train"
    return out


def initial_heading(head_rotation: np.ndarray) -> float:
    """The heading (radians about +y) of the head's forward axis (its local +z) in frame 0 of (T, 3, 3)
    head-to-world rotations: ``yaw_matrix(-heading)`` turns that axis onto +z."""
    forward = head_rotation[0, :, 2]
    return float(np.arctan2(forward[0], forward[2]))


def _missing(folder: Path) -> list[str]:
    missing = [f for f in REQUIRED_FILES if not (folder / f).is_file()]
    if not (folder / "rgb.mp4").is_file() and not (folder / "rgb").is_dir():
        missing.append("rgb.mp4 or rgb/")
    return missing


class EgoDanceDataset(Dataset):
    """Sample folders -> dicts of ``motion``, ``music``, ``head`` (and ``frames``), plus ``sample_id``.

    Motion, music and head targets are read once at construction; frames are decoded per item, or once and
    kept in memory with ``cache_frames`` (small sets: 150 frames at 64 px take 7 MB a window).
    ``window=None`` reads every sample whole (its motion and camera path's length), for long-form test and
    prediction.
    """

    def __init__(
        self,
        folders: list[Path],
        window: int | None = 150,
        fps: int = FPS,
        load_frames: bool = True,
        image_size: int = 224,
        music_cache_dir: str | None = None,
        cache_frames: bool = False,
        canonicalize_init_head: bool = False,
    ):
        self.folders = folders
        self.window = window
        self.canonicalize_init_head = canonicalize_init_head
        self.load_frames = load_frames
        self.image_size = image_size
        self.cache_frames = cache_frames
        self._frames: dict[int, torch.Tensor] = {}
        self.items = [self._read(f, fps, music_cache_dir) for f in folders]

    def _read(self, folder: Path, fps: int, cache_dir: str | None) -> dict:
        missing = _missing(folder)
        if missing:
            raise DatasetNotFoundError(f"{folder}: sample folder lacks {', '.join(missing)}")
        meta = read_meta(folder)
        motion = load_motion(folder / "motion.npz")
        if motion.poses is None or motion.trans is None:
            raise DataFileError(f"{folder / 'motion.npz'}: needs smpl_poses and smpl_trans")
        if abs(motion.fps - fps) > 1e-6:
            raise DataFileError(
                f"{folder / 'motion.npz'}: motion at {motion.fps} fps, the data module expects {fps}"
            )
        cam = load_npz(folder / "camera.npz")
        t = self.window or min(motion.poses.shape[0], len(cam["positions"]))
        if motion.poses.shape[0] < t:
            raise DataFileError(f"{folder}: {motion.poses.shape[0]} frames, shorter than the window of {t}")
        root = motion.trans[:t] / motion.scaling
        source = str(folder / "camera.npz")
        positions = check_finite(cam["positions"][:t], source, "positions", ("frame",))
        rotations = check_finite(cam["rotations"][:t], source, "rotations", ("frame",))
        head, head_rotation = head_pose_from_camera(positions, rotations)
        poses = torch.from_numpy(np.asarray(motion.poses[:t], dtype=np.float32))
        if self.canonicalize_init_head:  # turn about +y (through the origin) so the head faces +z in frame 0
            turn = yaw_matrix(-initial_heading(head_rotation))
            root, head, head_rotation = root @ turn.T, head @ turn.T, turn @ head_rotation
            orient = torch.from_numpy(turn).float() @ axis_angle_to_matrix(poses[:, 0])
            poses = torch.cat([matrix_to_axis_angle(orient)[:, None], poses[:, 1:]], dim=1)
        shift = np.array([root[0, 0], meta.get("scene", {}).get("floor_height", 0.0), root[0, 2]])
        music_meta = meta.get("music") or {}
        if not music_meta.get("path"):
            raise DatasetNotFoundError(
                f"{folder / 'meta.json'}: no music file for this sample (music.path is null); rebuild with "
                "`sm make-ego --music-dir DIR` pointing at the AIST++ music (<music id>.wav)"
            )
        analysis = extract_music_features(music_meta["path"], fps=fps, cache_dir=cache_dir)
        start = int(round(music_meta.get("start_s", 0.0) * fps))
        music = analysis.features[start : start + t]
        if music.shape[0] < t:  # the track ends inside the window: repeat the last frame
            music = np.concatenate([music, np.repeat(music[-1:], t - music.shape[0], axis=0)], axis=0)
        return {
            "sample_id": meta.get("sample_id", folder.name),
            "motion": encode_motion(poses, torch.from_numpy((root - shift).astype(np.float32))),
            "music": torch.from_numpy(music.astype(np.float32)),
            "head": torch.from_numpy((head - shift).astype(np.float32)),
            "music_path": str(music_meta["path"]),  # for the test loop's protocol beats
            "music_start_s": float(music_meta.get("start_s", 0.0)),
            "head_rotation": torch.from_numpy(head_rotation.astype(np.float32)),
        }

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict:
        item = dict(self.items[index])
        if self.load_frames:
            frames = self._frames.get(index)
            if frames is None:
                length = item["motion"].shape[0]
                rgb = torch.from_numpy(read_frames(self.folders[index])[:length]).permute(0, 3, 1, 2)
                frames = resize_frames(rgb.float() / 255.0, self.image_size)
                if self.cache_frames:
                    self._frames[index] = frames
            item["frames"] = frames
        return item


@dataclasses.dataclass(frozen=True)
class EgoDanceStatistics:
    """The training windows: ``motion`` (N, T, 24, 10) and ``music`` (N, T, 35), from which the EMM takes its
    preconditioning and music-normalisation statistics (:meth:`.model.EMM.set_data_statistics`)."""

    motion: torch.Tensor
    music: torch.Tensor


@dataclasses.dataclass(frozen=True, kw_only=True)
class EgoDanceContract(DataContract):
    """What EgoAIST++ windows fix for the module: the frame size, rate, music width (``network.music_dim``),
    window and its heading; the music-feature cache (read by the test loop, not linked) and the training
    windows (:class:`EgoDanceStatistics`)."""

    image_size: int
    fps: float
    music_dim: int
    window: int
    canonicalize_init_head: bool
    music_cache_dir: str | None = unlinked(None)
    statistics: EgoDanceStatistics | None = unlinked(None)


class EgoDanceDataModule(SplitDataModule):
    """EgoAIST++ windows from ``root`` (built by ``sm make-ego``).

    Args:
        root: the dataset folder (holding ``samples/``).
        window: frames per window T ([EgoMusic] supp. Table 2: 150 at 30 fps).
        fps: motion and music frame rate (30).
        batch_size: per-device batch (linked to the model).
        num_workers: DataLoader workers.
        load_frames: decode egocentric frames (False for music-only models).
        image_size: frames are resized to this square size (the ResNet input).
        val_fraction: share of motion sources held out for validation.
        test_fraction: share of non-AIST++ sources held out for testing.
        music_cache_dir: cache of music features (default ``~/.cache/skeleton_mamba/music``).
        cache_frames: keep the decoded frames in memory after their first use (small sets).
        canonicalize_init_head: turn each window so the head faces +z in its first frame (module docstring).
        full_sequences: the test split (``sm test``, ``sm predict``) reads every sample whole, one a batch,
            and the model dances sequences longer than ``window`` long-form; training and validation stay
            on windows.
    """

    def __init__(
        self,
        root: str = "data/egoaistpp",
        window: int = 150,
        fps: int = FPS,
        batch_size: int = 64,
        num_workers: int = 0,
        load_frames: bool = True,
        image_size: int = 224,
        val_fraction: float = 0.1,
        test_fraction: float = 0.1,
        music_cache_dir: str | None = None,
        cache_frames: bool = False,
        canonicalize_init_head: bool = False,
        full_sequences: bool = False,
    ):
        super().__init__(batch_size, num_workers)
        self.save_hyperparameters()
        self.root = Path(root)
        self.fps, self.image_size = fps, image_size  # linked to the model
        self.music_cache_dir = music_cache_dir  # the test loop's beats read the same cache (DataContract)
        self.music_dim = NUM_MUSIC_FEATURES  # the width of the 30 fps librosa features, linked too
        self.window, self.canonicalize_init_head = window, canonicalize_init_head  # linked: long-form

    def check_data(self) -> list[Path]:
        """The complete sample folders; raises :class:`DatasetNotFoundError` saying what is missing."""
        if not self.root.is_dir():
            raise DatasetNotFoundError(
                f"EgoAIST++ folder {self.root} does not exist; build it with "
                f"`sm make-ego --motion <AIST++ motions/> --out {self.root}` (see `sm make-ego --help`)"
            )
        folders = complete_samples(self.root)
        if not folders:
            where = self.root / SAMPLES
            state = "has no complete sample (no COMPLETE markers)" if where.is_dir() else "does not exist"
            raise DatasetNotFoundError(
                f"{where} {state}: {self.root} is not a finished `sm make-ego` build; run or resume "
                f"`sm make-ego --out {self.root} ...`"
            )
        return folders

    def split_folders(self) -> dict[str, list[Path]]:
        """The sample folders of each split (motion sources never straddle splits)."""
        folders = self.check_data()
        sources = []
        for folder in folders:
            meta = read_meta(folder)
            sources.append((meta.get("motion") or {}).get("source") or folder.name)
        split_of = self.assign_splits(sources)
        splits: dict[str, list[Path]] = {"train": [], "val": [], "test": []}
        for folder, source in zip(folders, sources, strict=True):
            splits[split_of[source]].append(folder)
        return splits

    def assign_splits(self, sources: list[str]) -> dict[str, str]:
        """Motion source -> split (:func:`assign_splits`)."""
        return assign_splits(sources, self.hparams.val_fraction, self.hparams.test_fraction)

    def setup(self, stage: str) -> None:
        if self.datasets:
            return
        hp = self.hparams
        for name, folders in self.split_folders().items():
            self.datasets[name] = EgoDanceDataset(
                folders,
                None if name == "test" and hp.full_sequences else hp.window,
                hp.fps,
                hp.load_frames,
                hp.image_size,
                hp.music_cache_dir,
                hp.cache_frames,
                hp.canonicalize_init_head,
            )
        if len(self.datasets["train"]) == 0 and stage == "fit":
            raise DatasetNotFoundError(f"{self.root}: every sample fell into val/test; no training windows")

    def loader_options(self, split: str) -> dict:
        """Whole sequences (``full_sequences``) differ in length: one a batch."""
        return {"batch_size": 1} if split == "test" and self.hparams.full_sequences else {}

    contract_class = EgoDanceContract

    @property
    def contract(self) -> EgoDanceContract:
        """What the data fixes for the model (:class:`EgoDanceContract`)."""
        return EgoDanceContract(
            image_size=self.image_size,
            fps=self.fps,
            music_dim=self.music_dim,
            window=self.window,
            canonicalize_init_head=self.canonicalize_init_head,
            music_cache_dir=self.music_cache_dir,
        )

    def training_statistics(self) -> EgoDanceStatistics | None:
        """The training windows (:class:`EgoDanceStatistics`); None before the training split is set up."""
        train = self.datasets.get("train")
        if train is None or len(train) == 0:
            return None
        return EgoDanceStatistics(
            motion=torch.stack([item["motion"] for item in train.items]),
            music=torch.stack([item["music"] for item in train.items]),
        )


class SyntheticEgoDanceDataModule(EgoDanceDataModule):
    """A small EgoAIST++-style set generated on first use (no download): the procedural dances and
    music of ``tasks/motion/synthetic`` placed in procedural rooms by the EgoAIST++ builder.

    Args:
        root: where the generated motions (``motions/``) and the built set (``ego/``) go.
        count: generated dance/music pairs (motion sources).
        duration_s: seconds per generated dance (windows of ``window / fps`` seconds are cut from it).
        stride_s: seconds between the windows cut from a dance (None: the window's length, non-overlapping);
            shorter strides give windows that start at more phases of the dance.
        frame_size: rendered egocentric frame size (pixels, square).
        num_rooms: procedural rooms to place the dances in.
        seed: generator seed.
        swing_side: ``random`` or ``music`` (the music's bars decide which way the dancers swing;
            :func:`~skeleton_mamba.tasks.motion.synthetic.synthesize_dance`).
        val_fraction: ``ceil(val_fraction * count)`` dances are held out for validation, stratified by
            style (:func:`~skeleton_mamba.tasks.motion.synthetic.splits.stratified_holdout`).
        test_fraction: ``ceil(test_fraction * count)`` dances are held out for testing, likewise.
        cache_frames: keep decoded frames in memory (default here: the set is small).

    Other arguments as :class:`EgoDanceDataModule`.
    """

    def __init__(
        self,
        root: str = "runs/egodance_demo/data",
        count: int = 9,
        duration_s: float = 10.0,
        stride_s: float | None = None,
        frame_size: int = 64,
        num_rooms: int = 2,
        seed: int = 0,
        swing_side: str = "random",
        window: int = 150,
        fps: int = FPS,
        batch_size: int = 4,
        num_workers: int = 0,
        load_frames: bool = True,
        image_size: int = 64,
        val_fraction: float = 0.1,
        test_fraction: float = 0.2,
        music_cache_dir: str | None = None,
        cache_frames: bool = True,
        canonicalize_init_head: bool = False,
        full_sequences: bool = False,
    ):
        super().__init__(
            str(Path(root) / "ego"),
            window,
            fps,
            batch_size,
            num_workers,
            load_frames,
            image_size,
            val_fraction,
            test_fraction,
            music_cache_dir,
            cache_frames,
            canonicalize_init_head,
            full_sequences,
        )
        self.source_root = Path(root).resolve()

    def check_data(self) -> list[Path]:
        """The complete sample folders; a missing set says how the demo builds it (not ``sm make-ego``)."""
        if not complete_samples(self.root):
            raise DatasetNotFoundError(
                f"the generated set {self.root} is missing or unfinished: the first `sm fit` of the recipe "
                f"(e.g. `sm fit --recipe egodance_demo.yaml`) generates it; a run folder copied without "
                f"its data folder ({self.source_root}) cannot find it"
            )
        return super().check_data()

    def assign_splits(self, sources: list[str]) -> dict[str, str]:
        """Generated dance -> split, stratified by style (class docstring)."""

        n = len(set(sources))
        val, test = (math.ceil(f * n) for f in (self.hparams.val_fraction, self.hparams.test_fraction))
        return stratified_holdout(sources, val, test)

    def prepare_data(self) -> None:
        """Generate and build the set unless a finished build is already there."""

        hp = self.hparams
        motions = self.source_root / "motions"
        settings = {"count": hp.count, "duration_s": hp.duration_s, "seed": hp.seed, "fps": float(hp.fps),
                    "swing_side": hp.swing_side}  # fmt: skip
        record = motions / "generator.json"
        if motions.is_dir() and any(motions.glob("*.npz")):
            found = read_json(record, error=DataFileError) if record.is_file() else None
            if found != settings:
                raise DataFileError(
                    f"{motions} holds dances generated with {found or 'unrecorded settings'}, "
                    f"not {settings}; "
                    f"remove {self.source_root} to generate them again, or choose another data root"
                )
        else:
            make_demo_set(motions, hp.count, hp.duration_s, hp.seed, float(hp.fps), hp.swing_side)
            with atomic_open(record, "w", encoding="utf-8") as f:
                f.write(json.dumps(settings))
        config = BuildConfig(
            out=str(self.source_root / "ego"),
            num_rooms=hp.num_rooms,
            fps=float(hp.fps),
            window_s=hp.window / hp.fps,
            stride_s=hp.stride_s,
            width=hp.frame_size,
            height=hp.frame_size,
            seed=hp.seed,
            workers=1,
            progress=progress_default(),  # a bar on a terminal, none in a log file
        )
        run_build(config, motions)
        self.root = self.source_root / "ego"


def data_module_from_hparams(hparams: dict) -> EgoDanceDataModule:
    """The data module a checkpoint was trained with, from its saved hyper-parameters
    (``datamodule_hyper_parameters``): the generated demo set when they have a ``count``, else an
    EgoAIST++ build; settings the class does not take are left out."""
    cls = SyntheticEgoDanceDataModule if "count" in hparams else EgoDanceDataModule
    accepted = inspect.signature(cls.__init__).parameters
    return cls(**{k: v for k, v in hparams.items() if k in accepted})
