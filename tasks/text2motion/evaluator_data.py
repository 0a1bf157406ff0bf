"""Batches for the T2M evaluator: GloVe caption features and normalised motions padded to 196 frames.

As ``Text2MotionDatasetV2``: a random caption of the clip, its tokens as GloVe vectors and POS one-hots
(:class:`~.glove.WordVectorizer`, ``sos`` + 20 tokens + ``eos``, 22 rows), a random crop whose length
is a multiple of 4, ``(x - Mean) / Std`` with the dataset statistics, zero padding to 196 frames.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.tasks.text2motion.data import HumanML3DDataModule, TextMotionDataset
from skeleton_mamba.tasks.text2motion.glove import HashedWordVectorizer, WordVectorizer
from skeleton_mamba.tasks.text2motion.humanml3d import MAX_MOTION_LENGTH, MotionClip, crop_length, load_clips

__all__ = ["EvaluatorDataset", "T2MEvaluatorDataModule"]


class EvaluatorDataset(TextMotionDataset):
    """Items ``{word_embs (22, 300), pos_onehot (22, 15), cap_len, motion (196, 263), length, caption}``.

    ``words`` is a :class:`~.glove.WordVectorizer` (or the :class:`~.glove.HashedWordVectorizer` stand-in).
    """

    def __init__(
        self,
        clips: list[MotionClip],
        mean: np.ndarray,
        std: np.ndarray,
        words: WordVectorizer | HashedWordVectorizer,
    ) -> None:
        super().__init__(clips, mean, std)
        self.words = words

    def __getitem__(self, index: int) -> dict:
        rng = np.random.default_rng(int(torch.randint(2**31 - 1, ())))
        clip = self.clips[index]
        caption = clip.captions[int(rng.integers(len(clip.captions)))]
        word_embs, pos_onehot, cap_len = self.words.encode(caption.tokens)
        length = crop_length(clip.length, rng, self.unit_length)
        start = int(rng.integers(clip.length - length + 1))
        motion = np.zeros((MAX_MOTION_LENGTH, clip.features.shape[1]), np.float32)
        motion[:length] = (clip.features[start : start + length] - self.mean) / self.std
        return {
            "word_embs": torch.from_numpy(word_embs),
            "pos_onehot": torch.from_numpy(pos_onehot),
            "cap_len": cap_len,
            "motion": torch.from_numpy(motion),
            "length": length,
            "caption": caption.text,
            "sample_id": clip.motion_id,
        }


class T2MEvaluatorDataModule(HumanML3DDataModule):
    """HumanML3D train / val splits for :class:`~.evaluator_module.T2MEvaluatorModule`.

    Args:
        root: HumanML3D folder (see :class:`~.data.HumanML3DDataModule`).
        glove_dir: folder with ``our_vab_data.npy``, ``our_vab_words.pkl``, ``our_vab_idx.pkl``.
        batch_size: per-device batch (32, as the evaluation's R-Precision groups).
        num_workers: data loader workers.
        limit: read at most this many ids per split.
    """

    def __init__(
        self,
        root: str = "data/humanml3d",
        glove_dir: str = "data/glove",
        batch_size: int = 32,
        num_workers: int = 4,
        limit: int | None = None,
    ) -> None:
        super().__init__(root, batch_size, num_workers, limit)
        self.glove_dir = Path(glove_dir)

    def setup(self, stage: str) -> None:
        self._check()
        mean, std = self._statistics()
        words = WordVectorizer(self.glove_dir)
        for split in ("train", "val") if stage == "fit" else ("val",):
            if split not in self.datasets:
                clips = load_clips(self.root, split, limit=self.limit)
                self.datasets[split] = EvaluatorDataset(clips, mean, std, words)

    def loader_options(self, split: str) -> dict:
        return {"drop_last": True}  # as the evaluation's groups of 32; default collation (fixed shapes)
