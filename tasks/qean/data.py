"""LightningDataModule for QEAN on [AIST++] ([QEAN] Sec. 4).

Layout read (``root`` = the AIST++ annotations folder)::

    <root>/motions/<name>.pkl      SMPL motions (smpl_poses, smpl_trans, smpl_scaling), 60 fps
    <music_dir>/<music id>.wav     music (.mp3 also accepted), e.g. mBR0.wav; default <root>/music

A split is a name or a path to a text file with one sequence name per line. A name ``X`` reads
``<root>/splits/crossmodal_X.txt`` when the AIST++ annotations hold it, else the toolkit's packaged crossmodal
list (``"train"``, ``"test"``; 980 / 20 names; no ``"val"`` ships). The 45 sequences of the AIST++ ignore
list are dropped.

Test protocol ([QEAN] Sec. 4.3: "40 generated motion sequences" of 1200 frames "from the AIST++ test
set"). The paper's text is [FACT]'s, and FACT's evaluation code (google-research/mint
``tools/preprocessing.py``, liruilong940607/mint ``tools/calculate_fid_scores.py``) generates for the
crossmodal **val + test** lists: 20 + 20 = 40 sequences, which share the 10 AIST++ test music pieces (each
piece danced by 4 sequences, i.e. 4 different seed motions per music). That reading is the default
(``test_split: [val, test]``); ``val`` comes from ``<root>/splits/crossmodal_val.txt`` of the annotations.

Samples (all at 60 fps, motion frame t aligned with music frame t):

* training: windows starting at ``s`` every ``window_stride`` frames: ``motion`` (seed_frames, 219) =
  frames ``[s, s + seed_frames)``, ``music`` (music_frames, 35) = music frames ``[s, s + music_frames)``,
  ``target`` (predict_frames, 219) = motion frames ``[s + seed_frames, s + seed_frames + predict_frames)``;
  with ``rollout_frames`` R > 0 the window also carries the R frames before it: ``motion`` (R + seed_frames)
  and ``music`` (R + music_frames) start R frames earlier (for :class:`~.module.QEANModule`'s rollouts);
* test: one item per sequence: its first ``seed_frames`` frames as ``seed`` and its music features
  zero-padded to the ``generate_frames + music_frames - 1`` frames that generation reads;
* predict: ``predict_seed`` (an AIST++ ``.pkl`` or our ``.npz``) and ``predict_music`` (any audio file);
  the dance lasts as long as the music (``generate_frames`` is the test's length).

``synthetic: true`` marks the files as generated stand-ins (the test table says its figures are not
comparable with [QEAN] Table 1) and, when ``<root>/motions`` does not exist, writes the SYNTHETIC demo set
of the live-dance demo there on first use
(:func:`~skeleton_mamba.tasks.motion.synthetic.aistpp_set.write_synthetic_aistpp`: procedural
beat-synchronised dances and synthesised drum tracks, ``splits/crossmodal_train.txt`` and
``crossmodal_val.txt``, the held-out split).

The 219-d motion vector is :mod:`.representation`'s; music features are the toolkit's cached 35-d ones.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

import torch
from torch.utils.data import DataLoader, Dataset
from tqdm import tqdm

from skeleton_mamba.errors import DataFileError, DatasetNotFoundError, InputError
from skeleton_mamba.tasks.motion.commands.cli_options import progress_default
from skeleton_mamba.tasks.motion.formats.aistpp import ignore_list, load_aistpp_motion, load_split, music_id
from skeleton_mamba.tasks.motion.formats.fact_features import FPS, features_to_joints, motion_to_features
from skeleton_mamba.tasks.motion.formats.motion_file import load_motion
from skeleton_mamba.tasks.motion.music.features import NUM_MUSIC_FEATURES, extract_music_features
from skeleton_mamba.tasks.motion.synthetic.aistpp_set import write_synthetic_aistpp
from skeleton_mamba.tasks.qean.generate import pad_music
from skeleton_mamba.tasks.training.base_data import ContractDataModule, DataContract, unlinked

__all__ = ["AISTPPDanceDataModule", "DanceWindowDataset", "QEANContract", "SequenceDataset"]

MUSIC_SUFFIXES = (".wav", ".mp3")


def _read_names(path: Path) -> list[str]:
    """Sequence names of a list file, one per line (``#`` comments and extensions dropped)."""
    if not path.is_file():
        raise FileNotFoundError(f"split list {path} not found")
    names = [ln.strip() for ln in path.read_text(encoding="utf-8").splitlines()]
    return [Path(n).stem for n in names if n and not n.startswith("#")]


class DanceWindowDataset(Dataset):
    """Training windows ``{motion, music, target, sample_id}`` over in-memory sequences (module docstring)."""

    def __init__(
        self,
        sequences: dict[str, tuple[torch.Tensor, torch.Tensor]],
        seed_frames: int,
        music_frames: int,
        predict_frames: int,
        stride: int,
        rollout_frames: int = 0,
    ) -> None:
        self.sequences = sequences
        self.lengths = (seed_frames + rollout_frames, music_frames + rollout_frames, predict_frames)
        seed_frames, music_frames = self.lengths[:2]
        self.index: list[tuple[str, int]] = []
        for name, (motion, music) in sequences.items():
            last = min(len(motion) - seed_frames - predict_frames, len(music) - music_frames)
            self.index.extend((name, s) for s in range(0, last + 1, stride))
        if not self.index:
            raise DataFileError(
                f"no training window fits: every sequence needs >= {seed_frames + predict_frames} motion "
                f"frames and >= {music_frames} music frames ({len(sequences)} sequences)"
            )

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        name, s = self.index[i]
        motion, music = self.sequences[name]
        seed, window, predict = self.lengths
        return {
            "motion": motion[s : s + seed],
            "music": music[s : s + window],
            "target": motion[s + seed : s + seed + predict],
            "sample_id": f"{name}@{s}",  # sequence and first frame (named in training errors)
        }


class SequenceDataset(Dataset):
    """Generation inputs ``{seed, music, name, music_path}``, one per sequence (test and predict)."""

    def __init__(self, items: list[dict]) -> None:
        self.items = items

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict:
        return self.items[i]


@dataclasses.dataclass(frozen=True, kw_only=True)
class QEANContract(DataContract):
    """What the AIST++ windows fix for QEAN: the music width and the window lengths (``network.*`` but
    ``generate_frames``), and the music-feature cache (read by the test loop, not linked)."""

    music_dim: int
    seed_frames: int
    music_frames: int
    predict_frames: int
    generate_frames: int
    music_cache_dir: str | None = unlinked(None)


class AISTPPDanceDataModule(ContractDataModule):
    """AIST++ motions and music for QEAN.

    Args:
        root: the AIST++ annotations folder (holding ``motions/``).
        music_dir: folder of ``<music id>.wav|.mp3`` files (default ``<root>/music``).
        train_split: ``"train"`` (crossmodal list) or a text file of names.
        test_split: one split or a list of splits generated at test time (default ``[val, test]``, the
            paper's 40 sequences; see the module docstring).
        reference_splits: splits whose full motions form the real set of FID and the normalisation of
            Dist (FACT/Bailando code: every AIST++ sequence minus the ignore list = train + val + test).
        seed_frames: seed motion frames (120).
        music_frames: music frames per window (240).
        predict_frames: frames predicted per window (20).
        generate_frames: frames generated after the seed at test time (1200 = 20 s); `sm predict` dances the
            whole music instead.
        window_stride: frames between training windows.
        rollout_frames: frames before each training window that it also carries (0: none, [QEAN]'s windows),
            for ``QEANModule.rollout_probability``; at most ``seed_frames`` (above ``predict_frames`` the
            module chains its predictions, so the whole seed can be the network's own).
        exclude_ignored: drop the AIST++ ignore list.
        batch_size: training batch (16).
        test_batch_size: sequences generated together at test and predict time.
        num_workers: DataLoader worker processes.
        music_cache_dir: cache folder for music features (default: the toolkit's).
        test_max_sequences: generate for only the first N test sequences (``None``: all; for quick checks).
        synthetic: the files are generated stand-ins in the AIST++ layout, not AIST++: the test table says
            that its figures are not comparable with [QEAN] Table 1; a SYNTHETIC demo set is written under
            ``root`` when it holds no ``motions/`` (module docstring).
        synthetic_count: dances in that demo set (the last ``synthetic_held_out`` are the ``val`` split).
        synthetic_held_out: held-out (``val``) dances of the demo set.
        synthetic_duration_s: length of each demo dance in seconds.
        predict_seed: seed motion file for ``sm predict`` (AIST++ ``.pkl`` or ``.npz``).
        predict_music: music file for ``sm predict``.
    """

    def __init__(
        self,
        root: str = "data/aistpp",
        music_dir: str | None = None,
        train_split: str = "train",
        test_split: str | list[str] | None = None,
        reference_splits: list[str] | None = None,
        seed_frames: int = 120,
        music_frames: int = 240,
        predict_frames: int = 20,
        generate_frames: int = 1200,
        window_stride: int = 1,
        rollout_frames: int = 0,
        exclude_ignored: bool = True,
        batch_size: int = 16,
        test_batch_size: int = 8,
        num_workers: int = 4,
        music_cache_dir: str | None = None,
        test_max_sequences: int | None = None,
        synthetic: bool = False,
        synthetic_count: int = 8,
        synthetic_held_out: int = 2,
        synthetic_duration_s: float = 12.0,
        predict_seed: str | None = None,
        predict_music: str | None = None,
    ) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.root = Path(root).expanduser()
        self.music_dir = Path(music_dir).expanduser() if music_dir else self.root / "music"
        self.reference_splits = (
            ["train", "val", "test"] if reference_splits is None else list(reference_splits)
        )
        if test_split is None:
            test_split = ["val", "test"]
        self.test_splits = [test_split] if isinstance(test_split, str) else list(test_split)
        if not 0 <= rollout_frames <= seed_frames:
            raise ValueError(f"rollout_frames must be 0 to {seed_frames} (seed_frames), got {rollout_frames}")
        if test_max_sequences is not None and test_max_sequences < 1:
            raise ValueError(f"test_max_sequences must be >= 1 or None, got {test_max_sequences}")
        self.synthetic = synthetic
        self.batch_size = batch_size
        self.seed_frames, self.music_frames = seed_frames, music_frames  # linked to the model
        self.music_dim = NUM_MUSIC_FEATURES  # the width of the 60 fps librosa features, linked too
        self.music_cache_dir = music_cache_dir  # the test loop's beats read the same cache (DataContract)
        self.predict_frames, self.generate_frames = predict_frames, generate_frames
        self._sequences: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}
        self.datasets: dict[str, Dataset] = {}
        if predict_seed is None and not synthetic:  # fail before the model is built; `sm predict` needs
            self.check_layout()  # no AIST++ copy, a synthetic set is written by prepare_data

    contract_class = QEANContract

    @property
    def contract(self) -> QEANContract:
        """What the data fixes for the model (:class:`QEANContract`)."""
        return QEANContract(
            music_dim=self.music_dim,
            seed_frames=self.seed_frames,
            music_frames=self.music_frames,
            predict_frames=self.predict_frames,
            generate_frames=self.generate_frames,
            music_cache_dir=self.music_cache_dir,
        )

    def prepare_data(self) -> None:
        """Write the SYNTHETIC demo set under ``root`` if ``synthetic`` asks for it and it has no motions."""
        h = self.hparams
        if h.synthetic and not (self.root / "motions").is_dir():
            write_synthetic_aistpp(self.root, h.synthetic_count, h.synthetic_duration_s, h.synthetic_held_out)

    # ----- files -----
    def check_layout(self) -> None:
        """Raise :class:`DatasetNotFoundError` naming the expected folders when they are missing."""
        if not (self.root / "motions").is_dir():
            raise DatasetNotFoundError(
                f"AIST++ motions not found: {(self.root / 'motions').resolve()} is not a folder.\n"
                "Download the AIST++ annotations (https://google.github.io/aistplusplus_dataset) and point "
                "the recipe at them with --data.init_args.root PATH (the folder holding motions/)."
            )
        if not self.music_dir.is_dir():
            raise DatasetNotFoundError(
                f"AIST++ music folder not found: {self.music_dir.resolve()}.\n"
                "Put the AIST Dance DB music as <music id>.wav (e.g. mBR0.wav) there, or pass "
                "--data.init_args.music_dir PATH."
            )

    def split_names(self, split: str) -> list[str]:
        """Names of a split (a name-list file, else the annotations' or the packaged crossmodal list), minus
        the ignore list."""
        path = Path(split).expanduser()
        annotated = self.root / "splits" / f"crossmodal_{split}.txt"  # the AIST++ annotations' own lists
        if path.suffix == ".txt" or path.is_file():
            names = _read_names(path)
        elif annotated.is_file():
            names = _read_names(annotated)
        elif split == "val":
            raise DatasetNotFoundError(
                f"AIST++ crossmodal val list not found: {annotated} (the annotations download ships it; "
                "skeleton_mamba does not). [QEAN]'s 40 test sequences are val + test; for the 20 test "
                "sequences only pass --data.init_args.test_split test"
            )
        else:
            names = load_split(split)
        if self.hparams.exclude_ignored:
            ignored = ignore_list()
            names = [n for n in names if n not in ignored]
        if not names:
            raise DataFileError(f"split {split!r} holds no sequence names")
        return names

    def music_file(self, name: str) -> Path:
        """The music file of a sequence (``<music_dir>/<music id>.wav`` or ``.mp3``)."""
        mid = music_id(name)
        for suffix in MUSIC_SUFFIXES:
            path = self.music_dir / f"{mid}{suffix}"
            if path.is_file():
                return path
        raise FileNotFoundError(f"music for {name} not found: {self.music_dir / mid}.wav (or .mp3)")

    def music_features(self, path: Path) -> torch.Tensor:
        """(T, 35) float32 music features at 60 fps (cached on disk by the toolkit)."""
        analysis = extract_music_features(path, fps=60, cache_dir=self.hparams.music_cache_dir)
        return torch.from_numpy(analysis.features)

    def sequence(self, name: str) -> tuple[torch.Tensor, torch.Tensor]:
        """``(motion (T, 219), music (T', 35))`` of one sequence, loaded once."""
        if name not in self._sequences:
            pkl = self.root / "motions" / f"{name}.pkl"
            if not pkl.is_file():
                raise FileNotFoundError(f"{pkl}: motion of split sequence {name} not found")
            motion = motion_to_features(load_aistpp_motion(pkl))
            self._sequences[name] = (motion, self.music_features(self.music_file(name)))
        return self._sequences[name]

    def _load(self, names: list[str], what: str) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
        bar = tqdm(names, desc=f"AIST++ {what}", disable=len(names) < 50 or not progress_default())
        return {n: self.sequence(n) for n in bar}

    def reference_joints(self) -> Iterator[torch.Tensor]:
        """Full-length joint positions (T, 24, 3) of every sequence of ``reference_splits`` (the real set)."""
        self.check_layout()
        names = dict.fromkeys(n for split in self.reference_splits for n in self.split_names(split))
        for name in names:
            yield features_to_joints(self.sequence(name)[0])

    # ----- datasets -----
    def _generation_item(
        self, name: str, seed: torch.Tensor, music: torch.Tensor, music_path: Path, frames: int | None = None
    ) -> dict:
        """One generation: the seed's first ``seed_frames``, the music padded for ``frames`` generated frames
        (``generate_frames`` unless given), and ``frames`` itself."""
        h = self.hparams
        if len(seed) < h.seed_frames:
            raise DataFileError(f"{name}: the seed motion has {len(seed)} frames, QEAN needs {h.seed_frames}")
        frames = h.generate_frames if frames is None else frames
        padded = pad_music(music[None], frames, h.music_frames)[0]
        return {
            "seed": seed[: h.seed_frames],
            "music": padded,
            "name": name,
            "music_path": str(music_path),
            "frames": frames,
        }

    def _predict_items(self) -> list[dict]:
        h = self.hparams
        if not h.predict_seed or not h.predict_music:
            raise InputError(
                "sm predict needs --data.init_args.predict_seed MOTION (.pkl or .npz) and "
                "--data.init_args.predict_music AUDIO"
            )
        seed_path, music_path = Path(h.predict_seed).expanduser(), Path(h.predict_music).expanduser()
        if not seed_path.is_file():
            raise FileNotFoundError(f"{seed_path}: seed motion not found")
        motion = load_aistpp_motion(seed_path) if seed_path.suffix == ".pkl" else load_motion(seed_path)
        name = f"{music_path.stem}_{seed_path.stem}"
        music = self.music_features(music_path)  # (T, 35): the whole song, its frame 0 at the seed's first
        frames = len(music) - h.seed_frames  # the song is danced to its end
        if frames < 1:
            raise DataFileError(
                f"{music_path}: {len(music) / FPS:.2f} s of music, no longer than the {h.seed_frames}-frame "
                f"seed ({h.seed_frames / FPS:.2f} s): nothing to dance"
            )
        return [self._generation_item(name, motion_to_features(motion), music, music_path, frames)]

    def setup(self, stage: str) -> None:
        h = self.hparams
        if stage in ("fit", "test"):
            self.prepare_data()  # also when a callback sets up a stage the trainer did not prepare
        if stage == "fit" and "train" not in self.datasets:
            self.check_layout()
            sequences = self._load(self.split_names(h.train_split), "train")
            self.datasets["train"] = DanceWindowDataset(
                sequences, h.seed_frames, h.music_frames, h.predict_frames, h.window_stride, h.rollout_frames
            )
        elif stage == "test" and "test" not in self.datasets:
            self.check_layout()
            names = list(dict.fromkeys(n for split in self.test_splits for n in self.split_names(split)))
            names = names[: h.test_max_sequences]
            items = []
            for name, (motion, music) in self._load(names, "test").items():
                items.append(self._generation_item(name, motion, music, self.music_file(name)))
            self.datasets["test"] = SequenceDataset(items)
        elif stage == "predict" and "predict" not in self.datasets:
            self.datasets["predict"] = SequenceDataset(self._predict_items())

    def train_dataloader(self) -> DataLoader:
        workers = self.hparams.num_workers
        return DataLoader(
            self.datasets["train"],
            batch_size=self.batch_size,
            shuffle=True,
            drop_last=len(self.datasets["train"]) >= self.batch_size,
            num_workers=workers,
            persistent_workers=workers > 0,
        )

    def test_dataloader(self) -> DataLoader:
        return DataLoader(self.datasets["test"], batch_size=self.hparams.test_batch_size)

    def predict_dataloader(self) -> DataLoader:
        return DataLoader(self.datasets["predict"], batch_size=1)
