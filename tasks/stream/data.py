"""Training data of the live dance model: AIST++-layout motions and music, 30 fps, causal features.

Layout read (as QEAN's ``AISTPPDanceDataModule``; ``root`` = the AIST++ annotations folder)::

    <root>/motions/<name>.pkl      SMPL motions (smpl_poses, smpl_trans, smpl_scaling), 60 fps
    <music_dir>/<music id>.wav     the music (default <root>/music)
    <root>/splits/crossmodal_<split>.txt   name lists (else the packaged AIST++ crossmodal lists)

Every sequence becomes joint tokens (T, 24, 12) at 30 fps (:func:`~.model.motion_to_tokens`) and the
causal music features (T, 34) of its track (:func:`~.features.music_features`), cut to the shorter of
the two; a training item is a window ``{motion (W, 24, 12), music (W, 34)}`` taken every
``window_stride`` frames. ``synthetic: true`` writes a SYNTHETIC demo set in this layout on first use
(the toolkit's beat-synchronised procedural dances and drum tracks, one music id per dance, names
``g<genre>_sBM_cAll_d<k>_m<genre><i>_ch01``) when ``<root>/motions`` does not exist; with
``synthetic_music: recordings`` its music is REAL recordings (the ``immich-memories-music`` package) and its
dances are choreographed to each recording's tracked beats and sections
(:mod:`~skeleton_mamba.tasks.motion.synthetic.recorded_music_set`: a fixed split whose held-out songs are
never written into the set).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch
from torch.utils.data import DataLoader, Dataset

from skeleton_mamba.errors import DataFileError, DatasetNotFoundError
from skeleton_mamba.tasks.motion.formats.aistpp import ignore_list, load_aistpp_motion, load_split, music_id
from skeleton_mamba.tasks.motion.music.audio_io import probe_audio
from skeleton_mamba.tasks.motion.music.features import load_audio
from skeleton_mamba.tasks.motion.synthetic import aistpp_set, recorded_music_set
from skeleton_mamba.tasks.stream.beat_phase import NUM_BEAT_FEATURES
from skeleton_mamba.tasks.stream.features import NUM_FEATURES, music_features
from skeleton_mamba.tasks.stream.model import motion_to_tokens
from skeleton_mamba.tasks.training.base_data import ContractDataModule, DataContract, unlinked

__all__ = ["SYNTHETIC_MUSIC", "StreamContract", "StreamDanceDataModule", "StreamStatistics"]

SYNTHETIC_MUSIC = ("drums", "recordings")  # the demo set's music: synthesised drum tracks, real recordings


def audio_rate(path: Path) -> int:
    """The sample rate of an audio file (raises naming the file when it is missing or unreadable)."""

    if not path.is_file():
        raise FileNotFoundError(f"{path}: music file not found")
    return probe_audio(path).sample_rate  # the one checked reader: rate, channels, duration in bounds


class WindowDataset(Dataset):
    """``{motion (W, 24, 12), music (W, 34)}`` windows over in-memory sequences."""

    def __init__(self, sequences: dict[str, tuple[torch.Tensor, torch.Tensor]], window: int, stride: int):
        self.sequences = sequences
        self.window = window
        self.index = [
            (name, s)
            for name, (motion, _) in sequences.items()
            for s in range(0, len(motion) - window + 1, stride)
        ]
        if not self.index:
            raise DataFileError(f"no sequence holds a window of {window} frames ({len(sequences)} sequences)")

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        name, s = self.index[i]
        motion, music = self.sequences[name]
        return {"motion": motion[s : s + self.window], "music": music[s : s + self.window]}


@dataclasses.dataclass(frozen=True)
class StreamStatistics:
    """``music``: every training music frame (N, 34), for the dancer's feature normalisation."""

    music: torch.Tensor


@dataclasses.dataclass(frozen=True, kw_only=True)
class StreamContract(DataContract):
    """What the windows fix for the streaming dancer: its music width, and the training music
    (:class:`StreamStatistics`)."""

    music_dim: int
    statistics: StreamStatistics | None = unlinked(None)


class StreamDanceDataModule(ContractDataModule):
    """AIST++-layout dances for the causal dance model (see the module docstring).

    Args:
        root: the AIST++ annotations folder (holding ``motions/``).
        music_dir: folder of ``<music id>.wav`` (default ``<root>/music``).
        train_split: ``"train"`` or a name-list file.
        val_split: a split validated with the teacher-forced loss, or ``None``.
        window_frames: frames per training window at 30 fps.
        window_stride: frames between window starts.
        batch_size: windows per batch.
        num_workers: DataLoader workers.
        synthetic: write a SYNTHETIC demo set under ``root`` when it holds no ``motions/``.
        synthetic_count: dances in the demo set (``recordings``: training recordings; the two test songs are
            added as the ``val`` split).
        synthetic_duration_s: length of each demo dance (``recordings``: the excerpt of each recording).
        synthetic_music: the demo set's music, ``"drums"`` (synthesised drum tracks) or ``"recordings"``
            (real recordings, :mod:`~skeleton_mamba.tasks.motion.synthetic.recorded_music_set`).
        beat_phase: append the causal beat phase to the music features (36 per frame, :mod:`.beat_phase`;
            the model's ``music_dim`` is linked to it; ``sm stream`` computes what the model was trained on).
    """

    def __init__(
        self,
        root: str = "data/aistpp",
        music_dir: str | None = None,
        train_split: str = "train",
        val_split: str | None = None,
        window_frames: int = 90,
        window_stride: int = 10,
        batch_size: int = 16,
        num_workers: int = 0,
        synthetic: bool = False,
        synthetic_count: int = 8,
        synthetic_duration_s: float = 12.0,
        synthetic_music: str = "drums",
        beat_phase: bool = False,
    ) -> None:
        super().__init__()
        if synthetic_music not in SYNTHETIC_MUSIC:
            raise ValueError(f"synthetic_music must be one of {SYNTHETIC_MUSIC}, got {synthetic_music!r}")
        if synthetic and synthetic_music == "recordings":  # before the model is built
            available = len(recorded_music_set.training_tracks())
            if not 1 <= synthetic_count <= available:
                raise ValueError(
                    f"synthetic_count must be 1 ... {available} (the training recordings of "
                    f"{recorded_music_set.PACKAGE}) with synthetic_music: recordings, got {synthetic_count}"
                )
        self.save_hyperparameters()
        self.root = Path(root).expanduser()
        self.music_dir = Path(music_dir).expanduser() if music_dir else self.root / "music"
        # the causal features' width (34, 36 with the beat phase), linked to the model
        self.music_dim = NUM_FEATURES + (NUM_BEAT_FEATURES if beat_phase else 0)
        self.datasets: dict[str, Dataset] = {}
        self._music: dict[Path, torch.Tensor] = {}  # features per track (AIST++ reuses each track)
        if not synthetic:  # fail before the model is built
            self.check_layout()

    def prepare_data(self) -> None:
        h = self.hparams
        if h.synthetic and not (self.root / "motions").is_dir():
            if h.synthetic_music == "recordings":
                recorded_music_set.write_recorded_music_aistpp(
                    self.root, h.synthetic_count, h.synthetic_duration_s
                )
            else:
                aistpp_set.write_synthetic_aistpp(self.root, h.synthetic_count, h.synthetic_duration_s)
        self.check_layout()

    @property
    def label(self) -> str:
        """What the demo set is (the demo prints it): synthetic dances, on drum tracks or recordings."""
        if self.hparams.synthetic_music == "recordings":
            return recorded_music_set.LABEL
        return aistpp_set.LABEL

    def check_layout(self) -> None:
        """Raise :class:`DatasetNotFoundError` saying where the motions go when they are missing."""
        if not (self.root / "motions").is_dir():
            raise DatasetNotFoundError(
                f"AIST++ motions not found: {(self.root / 'motions').resolve()} is not a folder.\n"
                "Download the AIST++ annotations (https://google.github.io/aistplusplus_dataset) and pass "
                "--data.init_args.root PATH, or train on the synthetic demo set: sm fit --recipe "
                "stream_dance_demo.yaml"
            )

    def split_names(self, split: str) -> list[str]:
        """Names of a split (a list file, ``<root>/splits/crossmodal_<split>.txt``, or the packaged list)."""
        path = Path(split).expanduser()
        local = self.root / "splits" / f"crossmodal_{split}.txt"
        if path.suffix == ".txt":
            source = path
        elif local.is_file():
            source = local
        else:
            return [n for n in load_split(split) if n not in ignore_list()]
        if not source.is_file():
            raise FileNotFoundError(f"split list {source} not found")
        lines = source.read_text(encoding="utf-8").splitlines()
        return [Path(n.strip()).stem for n in lines if n.strip() and not n.startswith("#")]

    def sequence(self, name: str) -> tuple[torch.Tensor, torch.Tensor]:
        """``(motion (T, 24, 12), music (T, 34))`` of one sequence at 30 fps."""
        pkl = self.root / "motions" / f"{name}.pkl"
        if not pkl.is_file():
            raise FileNotFoundError(f"{pkl}: motion of split sequence {name} not found")
        wav = self.music_dir / f"{music_id(name)}.wav"
        motion = motion_to_tokens(load_aistpp_motion(pkl))
        if wav not in self._music:
            # At the file's own rate through the same streaming resampler as ``sm stream``.
            rate = audio_rate(wav)
            features = music_features(load_audio(wav, rate), rate, beat_phase=self.hparams.beat_phase)
            self._music[wav] = torch.from_numpy(features)
        music = self._music[wav]
        n = min(len(motion), len(music))
        return motion[:n], music[:n]

    def setup(self, stage: str) -> None:
        h = self.hparams
        splits = {"train": h.train_split} if stage == "fit" else {}
        if stage in ("fit", "validate") and h.val_split:
            splits["val"] = h.val_split
        for key, split in splits.items():
            if key not in self.datasets:
                self.prepare_data()
                sequences = {n: self.sequence(n) for n in self.split_names(split)}
                self.datasets[key] = WindowDataset(sequences, h.window_frames, h.window_stride)

    def train_music(self) -> torch.Tensor:
        """Every training music frame (N, 34), for the model's feature normalisation."""
        return torch.cat([music for _, music in self.datasets["train"].sequences.values()])

    contract_class = StreamContract

    @property
    def contract(self) -> StreamContract:
        """What the data fixes for the model (:class:`StreamContract`)."""
        return StreamContract(music_dim=self.music_dim)

    def training_statistics(self) -> StreamStatistics | None:
        """Every training music frame (:class:`StreamStatistics`); None before the split is set up."""
        return StreamStatistics(music=self.train_music()) if "train" in self.datasets else None

    def train_dataloader(self) -> DataLoader:
        data = self.datasets["train"]
        return DataLoader(
            data,
            batch_size=self.hparams.batch_size,
            shuffle=True,
            drop_last=len(data) >= self.hparams.batch_size,
            num_workers=self.hparams.num_workers,
        )

    def val_dataloader(self) -> DataLoader:
        if "val" not in self.datasets:
            return []
        return DataLoader(self.datasets["val"], batch_size=self.hparams.batch_size)
