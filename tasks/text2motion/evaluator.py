"""The T2M evaluator networks ([T2M]) that embed texts and motions for the metrics.

Architectures as ``EricGuo5513/text-to-motion networks/modules.py`` (parameter names kept, so the
official ``checkpoints/t2m/text_mot_match/model/finest.tar`` loads into them):

- :class:`TextEncoderBiGRUCo`: GloVe 300-d + Linear(15 POS -> 300) -> Linear -> 512 -> BiGRU(512) ->
  last states of both directions -> MLP -> 512.
- :class:`MovementConvEncoder`: (B, T, 259) motion without foot contacts -> two Conv1d (k 4, s 2, p 1)
  with Dropout 0.2 and LeakyReLU 0.2 (T / 4 frames) -> Linear -> (B, T / 4, 512).
- :class:`MotionEncoderBiGRUCo`: Linear 512 -> 1024 -> BiGRU(1024) -> MLP -> 512.

:class:`T2MEvaluator` bundles the three and returns embeddings in input order (the original returns
them sorted by motion length). Motions must be normalised with the *evaluator's* statistics
(MDM ``t2m_mean.npy`` / ``t2m_std.npy``), which differ from the dataset's in the root and foot groups.
Scores are comparable to published numbers only with the official checkpoint and GloVe files.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import torch
from torch import nn
from torch.nn.utils.rnn import pack_padded_sequence

from skeleton_mamba.errors import CheckpointError
from skeleton_mamba.tasks.text2motion.glove import POS_ENUMERATOR
from skeleton_mamba.tasks.training.checkpoints import (
    check_finite_tensors,
    check_state_fits,
    load_checkpoint,
    state_shapes,
)

__all__ = [
    "TextEncoderBiGRUCo",
    "MovementConvEncoder",
    "MotionEncoderBiGRUCo",
    "T2MEvaluator",
    "load_evaluator",
]

UNIT_LENGTH = 4


def _init_weight(module: nn.Module) -> None:
    if isinstance(module, (nn.Conv1d, nn.Linear)):
        nn.init.xavier_normal_(module.weight)
        if module.bias is not None:
            nn.init.constant_(module.bias, 0)


def _head(hidden_size: int, output_size: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(hidden_size * 2, hidden_size),
        nn.LayerNorm(hidden_size),
        nn.LeakyReLU(0.2, inplace=True),
        nn.Linear(hidden_size, output_size),
    )


def _last_states(
    gru: nn.GRU, inputs: torch.Tensor, lengths: torch.Tensor, hidden: torch.Tensor
) -> torch.Tensor:
    """Final forward and backward states of a BiGRU over right-padded (B, T, C): -> (B, 2 H)."""
    packed = pack_padded_sequence(inputs, lengths.cpu(), batch_first=True, enforce_sorted=False)
    _, last = gru(packed, hidden.repeat(1, inputs.shape[0], 1).contiguous())
    return torch.cat([last[0], last[1]], dim=-1)


class TextEncoderBiGRUCo(nn.Module):
    """Caption embedding: word vectors (B, L, 300), POS one-hots (B, L, 15), lengths (B,) -> (B, 512)."""

    def __init__(
        self,
        word_size: int = 300,
        pos_size: int = len(POS_ENUMERATOR),
        hidden_size: int = 512,
        output_size: int = 512,
    ) -> None:
        super().__init__()
        self.pos_emb = nn.Linear(pos_size, word_size)
        self.input_emb = nn.Linear(word_size, hidden_size)
        self.gru = nn.GRU(hidden_size, hidden_size, batch_first=True, bidirectional=True)
        self.output_net = _head(hidden_size, output_size)
        for part in (self.input_emb, self.pos_emb, self.output_net):
            part.apply(_init_weight)
        self.hidden = nn.Parameter(torch.randn(2, 1, hidden_size))

    def forward(
        self, word_embs: torch.Tensor, pos_onehot: torch.Tensor, cap_lens: torch.Tensor
    ) -> torch.Tensor:
        inputs = self.input_emb(word_embs + self.pos_emb(pos_onehot))
        return self.output_net(_last_states(self.gru, inputs, cap_lens, self.hidden))


class MovementConvEncoder(nn.Module):
    """Movement features: (B, T, 259) -> (B, T / 4, 512)."""

    def __init__(self, input_size: int = 259, hidden_size: int = 512, output_size: int = 512) -> None:
        super().__init__()
        self.main = nn.Sequential(
            nn.Conv1d(input_size, hidden_size, 4, 2, 1),
            nn.Dropout(0.2, inplace=True),
            nn.LeakyReLU(0.2, inplace=True),
            nn.Conv1d(hidden_size, output_size, 4, 2, 1),
            nn.Dropout(0.2, inplace=True),
            nn.LeakyReLU(0.2, inplace=True),
        )
        self.out_net = nn.Linear(output_size, output_size)
        self.main.apply(_init_weight)
        self.out_net.apply(_init_weight)

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return self.out_net(self.main(inputs.transpose(1, 2)).transpose(1, 2))


class MotionEncoderBiGRUCo(nn.Module):
    """Motion embedding: movements (B, T', 512), lengths T' (B,) -> (B, 512)."""

    def __init__(self, input_size: int = 512, hidden_size: int = 1024, output_size: int = 512) -> None:
        super().__init__()
        self.input_emb = nn.Linear(input_size, hidden_size)
        self.gru = nn.GRU(hidden_size, hidden_size, batch_first=True, bidirectional=True)
        self.output_net = _head(hidden_size, output_size)
        self.input_emb.apply(_init_weight)
        self.output_net.apply(_init_weight)
        self.hidden = nn.Parameter(torch.randn(2, 1, hidden_size))

    def forward(self, inputs: torch.Tensor, m_lens: torch.Tensor) -> torch.Tensor:
        return self.output_net(_last_states(self.gru, self.input_emb(inputs), m_lens, self.hidden))


def _load_checked(module: nn.Module, state: dict, source: str) -> None:
    """``module.load_state_dict(state)`` once its tensors are finite and their names and shapes fit (one line
    naming ``source`` and the first mismatch otherwise)."""
    bad = next((k for k, v in state.items() if not isinstance(v, torch.Tensor)), None)
    if bad is not None:
        raise CheckpointError(f"{source}: {bad!r} is a {type(state[bad]).__name__}, not a tensor")
    check_finite_tensors(state, source)
    check_state_fits(module, state_shapes(state), source)
    module.load_state_dict(state)


class T2MEvaluator(nn.Module):
    """Text and motion encoders of the T2M evaluation protocol.

    Args:
        feature_dim: motion feature size (263 HumanML3D, 251 KIT-ML); the last 4 (foot contacts) are unused.
        comparable: ``True`` only when the official checkpoint was loaded; results of an evaluator
            trained here must be labelled as not comparable with published numbers.
        word_size: word vector size (official: 300).
        text_hidden: text encoder width (official: 512).
        movement_hidden: movement encoder width (official: 512).
        movement_latent: movement latent size (official: 512).
        motion_hidden: motion encoder width (official: 1024).
        embedding_dim: the shared text / motion embedding size (official: 512).

    The defaults are the official sizes.
    """

    def __init__(
        self,
        feature_dim: int = 263,
        comparable: bool = False,
        word_size: int = 300,
        text_hidden: int = 512,
        movement_hidden: int = 512,
        movement_latent: int = 512,
        motion_hidden: int = 1024,
        embedding_dim: int = 512,
    ) -> None:
        super().__init__()
        pos_size = len(POS_ENUMERATOR)
        self.text_encoder = TextEncoderBiGRUCo(word_size, pos_size, text_hidden, embedding_dim)
        self.movement_encoder = MovementConvEncoder(feature_dim - 4, movement_hidden, movement_latent)
        self.motion_encoder = MotionEncoderBiGRUCo(movement_latent, motion_hidden, embedding_dim)
        self.comparable = comparable

    @classmethod
    def from_checkpoint(cls, path: str | PathLike[str], feature_dim: int = 263, **sizes: int) -> T2MEvaluator:
        """Load the official ``finest.tar`` (keys ``text_encoder``, ``movement_encoder``, ``motion_encoder``).

        Read with :func:`~skeleton_mamba.tasks.training.checkpoints.load_checkpoint` (``weights_only=True``):
        tensors and plain values only, nothing executed.
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: T2M evaluator checkpoint not found")
        checkpoint = load_checkpoint(path)
        model = cls(feature_dim, comparable=True, **sizes)
        for key in ("text_encoder", "movement_encoder", "motion_encoder"):
            if not isinstance(checkpoint.get(key), dict):
                raise CheckpointError(f"{path}: no {key!r} state dict (keys: {sorted(map(str, checkpoint))})")
            _load_checked(getattr(model, key), checkpoint[key], f"{path} [{key}]")
        return model.eval()

    @classmethod
    def from_lightning_checkpoint(
        cls, path: str | PathLike[str], feature_dim: int = 263, **sizes: int
    ) -> T2MEvaluator:
        """The evaluator of a ``sm fit --recipe t2m_evaluator.yaml`` checkpoint (``evaluator.*`` keys).

        Not comparable with published numbers (``comparable`` is False).
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: T2M evaluator checkpoint not found")
        checkpoint = load_checkpoint(path)
        state = checkpoint.get("state_dict", {}) if isinstance(checkpoint, dict) else {}
        prefix = "evaluator."
        weights = {k[len(prefix) :]: v for k, v in state.items() if k.startswith(prefix)}
        if not weights:
            raise CheckpointError(
                f"{path}: no 'evaluator.*' weights in its state_dict (not a T2MEvaluatorModule file)"
            )
        model = cls(feature_dim, comparable=False, **sizes)
        _load_checked(model, weights, str(path))
        return model.eval()

    def embed_text(
        self, word_embs: torch.Tensor, pos_onehot: torch.Tensor, cap_lens: torch.Tensor
    ) -> torch.Tensor:
        """(B, 22, 300), (B, 22, 15), (B,) -> (B, 512)."""
        return self.text_encoder(word_embs.float(), pos_onehot.float(), cap_lens)

    def embed_motion(self, motions: torch.Tensor, m_lens: torch.Tensor) -> torch.Tensor:
        """Evaluator-normalised motions (B, T, 263) with lengths (B,) (multiples of 4) -> (B, 512)."""
        movements = self.movement_encoder(motions[..., :-4].float())
        return self.motion_encoder(movements, torch.div(m_lens, UNIT_LENGTH, rounding_mode="floor"))


def load_evaluator(path: str | PathLike[str] | None, feature_dim: int = 263, seed: int = 0) -> T2MEvaluator:
    """The evaluator for the T2M protocol.

    Args:
        path: the official ``finest.tar`` (comparable), a Lightning ``.ckpt`` of
            :class:`~.evaluator_module.T2MEvaluatorModule` (trained here), or ``None`` for a randomly
            initialised evaluator drawn with ``seed`` (smoke runs only). The last two are not comparable.
        feature_dim: motion feature size (263).
        seed: initialisation seed of the random evaluator (the global RNG is left untouched).
    """
    if path is None:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            return T2MEvaluator(feature_dim, comparable=False).eval()
    if Path(path).suffix == ".ckpt":
        return T2MEvaluator.from_lightning_checkpoint(path, feature_dim)
    return T2MEvaluator.from_checkpoint(path, feature_dim)
