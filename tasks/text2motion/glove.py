"""The T2M evaluator's word features: GloVe vectors plus a 15-way POS one-hot (``WordVectorizer``).

Files (``EricGuo5513/text-to-motion utils/word_vectorizer.py``; downloaded by MDM
``prepare/download_glove.sh``) in one folder, prefix ``our_vab``::

    our_vab_data.npy   (V, 300) float vectors
    our_vab_words.pkl  list of V words
    our_vab_idx.pkl    dict word -> row

A token ``word/POS`` maps to the word's vector (``unk`` when unknown, with POS ``OTHER``) and a POS
one-hot; words of the five "VIP" lists override the spaCy POS. Captions become ``sos`` + at most 20
tokens + ``eos``, padded with ``unk/OTHER`` to 22 (``Text2MotionDatasetV2``). The pickles are read with
the toolkit's restricted unpickler.

Without the GloVe files, :class:`HashedWordVectorizer` gives every word a fixed random vector (seeded by
the word's CRC-32), so a randomly initialised evaluator still runs the protocol end to end; such scores
are not comparable with published numbers.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from os import PathLike
from pathlib import Path

import numpy as np

from skeleton_mamba.tasks.motion.io.safe_pickle import safe_load_pickle
from skeleton_mamba.tasks.motion.io.value_checks import check_finite, load_npy

__all__ = [
    "POS_ENUMERATOR",
    "VIP_WORDS",
    "MAX_TEXT_LENGTH",
    "WordVectorizer",
    "HashedWordVectorizer",
    "pad_tokens",
]

POS_ENUMERATOR = {
    "VERB": 0,
    "NOUN": 1,
    "DET": 2,
    "ADP": 3,
    "NUM": 4,
    "AUX": 5,
    "PRON": 6,
    "ADJ": 7,
    "ADV": 8,
    "Loc_VIP": 9,
    "Body_VIP": 10,
    "Obj_VIP": 11,
    "Act_VIP": 12,
    "Desc_VIP": 13,
    "OTHER": 14,
}
# fmt: off
VIP_WORDS: dict[str, tuple[str, ...]] = {
    "Loc_VIP": ("left", "right", "clockwise", "counterclockwise", "anticlockwise", "forward", "back",
                "backward", "up", "down", "straight", "curve"),
    "Body_VIP": ("arm", "chin", "foot", "feet", "face", "hand", "mouth", "leg", "waist", "eye", "knee",
                 "shoulder", "thigh"),
    "Obj_VIP": ("stair", "dumbbell", "chair", "window", "floor", "car", "ball", "handrail", "baseball",
                "basketball"),
    "Act_VIP": ("walk", "run", "swing", "pick", "bring", "kick", "put", "squat", "throw", "hop", "dance",
                "jump", "turn", "stumble", "dance", "stop", "sit", "lift", "lower", "raise", "wash", "stand",
                "kneel", "stroll", "rub", "bend", "balance", "flap", "jog", "shuffle", "lean", "rotate",
                "spin", "spread", "climb"),
    "Desc_VIP": ("slowly", "carefully", "fast", "careful", "slow", "quickly", "happy", "angry", "sad",
                 "happily", "angrily", "sadly"),
}
# fmt: on
MAX_TEXT_LENGTH = 20


def pad_tokens(tokens: Sequence[str], max_length: int = MAX_TEXT_LENGTH) -> tuple[list[str], int]:
    """``sos`` + tokens (cut to ``max_length``) + ``eos``, padded with ``unk/OTHER`` to ``max_length + 2``.

    Returns:
        ``(tokens, sentence_length)`` with the length counting ``sos`` and ``eos``.
    """
    words = ["sos/OTHER", *list(tokens)[:max_length], "eos/OTHER"]
    length = len(words)
    return words + ["unk/OTHER"] * (max_length + 2 - length), length


class _TokenFeatures:
    """``word/POS`` token -> (word vector, POS one-hot); subclasses provide :meth:`vector`."""

    dim: int

    def vector(self, word: str) -> np.ndarray | None:
        """The (dim,) vector of ``word``, ``None`` when unknown."""
        raise NotImplementedError

    @staticmethod
    def pos_one_hot(pos: str) -> np.ndarray:
        """(15,) one-hot of a POS tag (unknown tags -> ``OTHER``)."""
        vector = np.zeros(len(POS_ENUMERATOR), np.float32)
        vector[POS_ENUMERATOR.get(pos, POS_ENUMERATOR["OTHER"])] = 1.0
        return vector

    def __getitem__(self, token: str) -> tuple[np.ndarray, np.ndarray]:
        word, _, pos = token.partition("/")
        vector = self.vector(word)
        if vector is None:
            return self.vector("unk"), self.pos_one_hot("OTHER")
        vip = next((key for key, values in VIP_WORDS.items() if word in values), None)
        return vector, self.pos_one_hot(vip or pos)

    def encode(self, tokens: Sequence[str]) -> tuple[np.ndarray, np.ndarray, int]:
        """Padded caption -> word vectors (22, dim), POS one-hots (22, 15) and the sentence length."""
        padded, length = pad_tokens(tokens)
        pairs = [self[t] for t in padded]
        return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs]), length


class WordVectorizer(_TokenFeatures):
    """GloVe vector and POS one-hot of ``word/POS`` tokens.

    Args:
        root: folder holding ``{prefix}_data.npy``, ``{prefix}_words.pkl`` and ``{prefix}_idx.pkl``.
        prefix: file prefix (``our_vab``).
    """

    def __init__(self, root: str | PathLike[str], prefix: str = "our_vab") -> None:
        root = Path(root)
        paths = [root / f"{prefix}_{suffix}" for suffix in ("data.npy", "words.pkl", "idx.pkl")]
        for path in paths:
            if not path.is_file():
                raise FileNotFoundError(f"{path}: missing GloVe file of the T2M evaluator")
        vectors = load_npy(paths[0])
        words, word_to_row = safe_load_pickle(paths[1]), safe_load_pickle(paths[2])
        if not isinstance(words, list) or not isinstance(word_to_row, dict):
            raise ValueError(f"{root}: expected a word list in {paths[1].name} and a dict in {paths[2].name}")
        if vectors.ndim != 2 or not np.issubdtype(vectors.dtype, np.number):
            raise ValueError(f"{paths[0]}: expected numeric (V, dim) vectors, got shape {vectors.shape}")
        check_finite(vectors, str(paths[0]), "vectors", ("row",))
        self.word_to_vector = {w: vectors[word_to_row[w]].astype(np.float32) for w in words}
        if "unk" not in self.word_to_vector:
            raise ValueError(f"{paths[1]}: the vocabulary has no 'unk' entry")
        self.dim = int(vectors.shape[1])

    def vector(self, word: str) -> np.ndarray | None:
        return self.word_to_vector.get(word)


class HashedWordVectorizer(_TokenFeatures):
    """Stand-in for GloVe: word -> N(0, I / dim) vector drawn with seed ``crc32(word) + seed``.

    Every word is known (no ``unk`` substitution), so the POS one-hots follow the tokens' tags.

    Args:
        dim: vector size (300 as GloVe).
        seed: offset of the per-word seeds.
    """

    def __init__(self, dim: int = 300, seed: int = 0) -> None:
        self.dim = dim
        self.seed = seed
        self._cache: dict[str, np.ndarray] = {}

    def vector(self, word: str) -> np.ndarray:
        if word not in self._cache:
            rng = np.random.default_rng(zlib.crc32(word.encode("utf-8")) + self.seed)
            self._cache[word] = (rng.standard_normal(self.dim) / np.sqrt(self.dim)).astype(np.float32)
        return self._cache[word]
