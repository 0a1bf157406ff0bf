"""A pluggable pretrained audio encoder (transformers, local checkpoint) as the stand-in for Jukebox.

[EgoMusic] and [EDGE] condition on [Jukebox] layer-66 features (4800-d at 30 fps, EDGE
``data/audio_extraction/jukebox_features.py``), which need the multi-GB Jukebox weights and "~24 hrs and
~50 GB" to precompute AIST++ (EDGE README): far too large here. This module runs any *encoder-only*
transformers audio model saved in a local folder (``AutoModel`` +
``AutoFeatureExtractor``: wav2vec2, HuBERT, WavLM, data2vec-audio, MERT with ``trust_remote_code``) and
returns per-motion-frame embeddings ``(T, D)``: the model's hidden states (last layer, or ``layer``) are
linearly resampled in time from the model's frame rate (50 Hz for wav2vec2-style models) to the motion fps.
Nothing is downloaded: loading uses ``local_files_only=True``.

Long audio is encoded in ``chunk_seconds`` pieces (attention cost is quadratic in length) whose frame
sequences are concatenated before resampling. :meth:`PretrainedAudioEncoder.encode_file` caches results
on disk keyed by the audio content, the checkpoint (config content, weight file names/sizes/mtimes) and
every setting.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from skeleton_mamba.tasks.motion.io.cache import FeatureCache
from skeleton_mamba.tasks.motion.music.features import load_audio
from skeleton_mamba.tasks.motion.music.jit_lock import librosa_calls

__all__ = ["PretrainedAudioEncoder", "resample_frames"]

_WEIGHT_SUFFIXES = (".safetensors", ".bin", ".pt", ".pth", ".ckpt")


def resample_frames(frames: torch.Tensor, num_frames: int) -> torch.Tensor:
    """Linearly resample ``(N, D)`` frames to ``(num_frames, D)`` (frame centres spread uniformly)."""
    if frames.ndim != 2:
        raise ValueError(f"frames must be (N, D), got {tuple(frames.shape)}")
    if num_frames < 1:
        raise ValueError(f"num_frames must be >= 1, got {num_frames}")
    x = frames.T[None]  # (1, D, N)
    return F.interpolate(x, size=num_frames, mode="linear", align_corners=False)[0].T


def _checkpoint_fingerprint(model_dir: Path) -> str:
    digest = hashlib.sha256()
    for f in sorted(model_dir.iterdir()):
        if f.suffix == ".json":
            digest.update(f.name.encode() + f.read_bytes())
        elif f.suffix in _WEIGHT_SUFFIXES:
            st = f.stat()
            digest.update(f"{f.name}:{st.st_size}:{st.st_mtime_ns}".encode())
    return digest.hexdigest()[:16]


class PretrainedAudioEncoder(nn.Module):
    """Frozen (by default) transformers audio encoder giving ``(T, D)`` embeddings at the motion fps.

    Args:
        model_path: local folder with ``config.json``, weights and ``preprocessor_config.json``.
        fps: motion frame rate of the output (EDGE / EgoMusic: 30).
        layer: index into ``hidden_states`` (0 = after the feature projection); ``None`` = last layer.
        chunk_seconds: encode long audio in pieces of this length (``None``: in one piece).
        trust_remote_code: allow the checkpoint folder's own model code (MERT); still no network.
        freeze: put the model in eval mode and disable its gradients.
    """

    def __init__(
        self,
        model_path: str,
        fps: float = 30.0,
        layer: int | None = None,
        chunk_seconds: float | None = 30.0,
        trust_remote_code: bool = False,
        freeze: bool = True,
    ) -> None:
        super().__init__()
        from transformers import AutoFeatureExtractor, AutoModel  # lazy: transformers' import is slow

        self.model_dir = Path(model_path).expanduser()
        if not (self.model_dir / "config.json").is_file():
            raise FileNotFoundError(f"{self.model_dir}: not a transformers checkpoint (no config.json)")
        try:
            self.feature_extractor = AutoFeatureExtractor.from_pretrained(
                self.model_dir, local_files_only=True, trust_remote_code=trust_remote_code
            )
            self.model = AutoModel.from_pretrained(
                self.model_dir, local_files_only=True, trust_remote_code=trust_remote_code
            )
        except (OSError, ValueError) as err:
            raise ValueError(f"{self.model_dir}: cannot load the audio model ({err})") from err
        if getattr(self.model.config, "is_encoder_decoder", False):
            raise ValueError(f"{self.model_dir}: encoder-decoder models are not supported; use an encoder")
        self.sampling_rate = int(self.feature_extractor.sampling_rate)
        self.fps = float(fps)
        self.layer = layer
        self.chunk_seconds = chunk_seconds
        self.frozen = freeze
        if freeze:
            self.model.eval()
            self.model.requires_grad_(False)

    @property
    def embedding_dim(self) -> int:
        """``D`` of the output (the model's hidden size)."""
        return int(self.model.config.hidden_size)

    def train(self, mode: bool = True) -> PretrainedAudioEncoder:
        super().train(mode)
        if self.frozen:
            self.model.eval()
        return self

    def _encode_piece(self, audio: np.ndarray) -> torch.Tensor:
        inputs = self.feature_extractor(audio, sampling_rate=self.sampling_rate, return_tensors="pt")
        device = next(self.model.parameters()).device
        inputs = {k: v.to(device) for k, v in inputs.items()}
        with torch.set_grad_enabled(not self.frozen and torch.is_grad_enabled()):
            out = self.model(**inputs, output_hidden_states=self.layer is not None)
        hidden = out.last_hidden_state if self.layer is None else out.hidden_states[self.layer]
        if hidden.ndim != 3 or hidden.shape[0] != 1:
            raise ValueError(f"{self.model_dir}: expected (1, N, D) hidden states, got {tuple(hidden.shape)}")
        return hidden[0]

    def forward(self, audio: torch.Tensor | np.ndarray, num_frames: int | None = None) -> torch.Tensor:
        """Embed mono audio sampled at :attr:`sampling_rate`.

        Args:
            audio: ``(N,)`` waveform at ``self.sampling_rate`` Hz.
            num_frames: output length ``T``; default ``round(N / sampling_rate * fps)``.

        Returns:
            ``(T, D)`` float32 embeddings, one row per motion frame.
        """
        if isinstance(audio, torch.Tensor):
            audio = audio.detach().cpu().numpy()
        wave = np.asarray(audio, dtype=np.float32)
        if wave.ndim != 1 or wave.size == 0:
            raise ValueError(f"audio must be a non-empty (N,) waveform, got shape {wave.shape}")
        if num_frames is None:
            num_frames = max(1, round(wave.size / self.sampling_rate * self.fps))
        step = wave.size
        if self.chunk_seconds is not None:
            step = max(1, int(self.chunk_seconds * self.sampling_rate))
        pieces = [self._encode_piece(wave[i : i + step]) for i in range(0, wave.size, step)]
        return resample_frames(torch.cat(pieces).float(), num_frames)

    def encode(self, audio: np.ndarray, sr: int, num_frames: int | None = None) -> torch.Tensor:
        """Embed ``(N,)`` audio at any sample rate (resampled with librosa first)."""
        audio = np.asarray(audio, dtype=np.float32)
        if sr != self.sampling_rate:
            with librosa_calls() as librosa:
                audio = librosa.resample(audio, orig_sr=sr, target_sr=self.sampling_rate)
        return self(audio, num_frames)

    def encode_file(
        self,
        path: str | os.PathLike,
        num_frames: int | None = None,
        cache_dir: str | os.PathLike | None = None,
        use_cache: bool = True,
    ) -> torch.Tensor:
        """Embed an audio file, with the on-disk cache (default ``~/.cache/skeleton_mamba/audio_encoder``)."""

        settings = {
            "kind": "pretrained_audio_encoder",
            "checkpoint": _checkpoint_fingerprint(self.model_dir),
            "fps": self.fps,
            "layer": self.layer,
            "chunk_seconds": self.chunk_seconds,
            "num_frames": num_frames,
        }
        cache = FeatureCache("audio_encoder", cache_dir, enabled=use_cache)
        key = cache.key(path, settings)
        cached = cache.load(key)
        if cached is not None and cached.ndim == 2 and cached.shape[1] == self.embedding_dim:
            return torch.from_numpy(cached)
        wave = load_audio(path, self.sampling_rate)
        embedding = self(wave, num_frames)
        cache.store(key, embedding.detach().cpu().numpy())
        return embedding
