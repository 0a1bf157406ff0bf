"""EMM condition encoders ([EgoMusic] supp. Table 1 rows 1-3, Sec. 6.2).

- :class:`MusicEncoder`: per-frame music features (B, T, L) -> Linear -> 2 Transformer encoder layers ->
  (B, T, Dc). The supplement uses Jukebox (L = 4800); the original code and our default use the 35-d
  librosa feature at 30 fps (``tasks/motion/music/features.py``); ``music_dim`` selects either.
- :class:`VisionEncoder`: egocentric frames (B, T, 3, H, W) -> kornia resize + ImageNet normalisation ->
  ResNet (``transformers.ResNetModel``; pretrained from a Hugging Face id such as ``microsoft/resnet-50``
  or a local folder (:func:`load_resnet`), else random init with a warning) -> pooled feature -> MLP ->
  (B, T, Dc).
- :class:`FusionModule`: music and vision tokens (each (B, T, Dc), plus a modality embedding) are joined
  along time, mixed by 2 Transformer encoder layers, and the two tokens of each frame are averaged back to
  (B, T, Dc) (the exact wiring is unpublished; the authors' rewrite lists it as missing).
"""

from __future__ import annotations

import copy
import warnings
from pathlib import Path

import kornia
import torch
from torch import nn
from transformers import ResNetConfig, ResNetModel

from skeleton_mamba.errors import RandomWeightsWarning
from skeleton_mamba.pretrained.checks import building_on_meta
from skeleton_mamba.tasks.egodance.frames import resize_frames
from skeleton_mamba.tasks.motion.body.statistics import channel_statistics
from skeleton_mamba.tasks.motion.music.features import NUM_MUSIC_FEATURES
from skeleton_mamba.tasks.training.diffusion.embedding import sinusoidal_embedding

__all__ = [
    "transformer_encoder",
    "load_resnet",
    "MusicEncoder",
    "VisionEncoder",
    "FusionModule",
]

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def transformer_encoder(
    dim: int, layers: int, heads: int, ff_dim: int, dropout: float
) -> nn.TransformerEncoder:
    """Pre-norm GELU Transformer encoder over (B, S, dim)."""
    layer = nn.TransformerEncoderLayer(
        dim, heads, ff_dim, dropout, activation="gelu", batch_first=True, norm_first=True
    )
    return nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)


def load_resnet(name_or_path: str) -> ResNetModel:
    """A pretrained ``transformers`` ResNet from a local ``save_pretrained`` folder or a Hugging Face id.

    A model id is downloaded once into the Hugging Face cache (``HF_HOME``) and read from there afterwards.
    Offline without a cached copy (or with a wrong id) it raises one ``OSError`` that says how to point at a
    local copy or to choose a random encoder explicitly.
    """
    path = Path(name_or_path).expanduser()
    if building_on_meta():  # sizes only: the architecture of its config, no weights read
        return ResNetModel(ResNetConfig.from_pretrained(path if path.is_dir() else name_or_path))
    if path.is_dir():
        return ResNetModel.from_pretrained(path)
    if path.exists() or name_or_path.startswith((".", "/", "~")) or name_or_path.count("/") != 1:
        raise FileNotFoundError(
            f"ResNet {name_or_path!r}: not a folder (a `save_pretrained` output) nor a Hugging Face model id "
            "such as 'microsoft/resnet-50'"
        )
    try:
        return ResNetModel.from_pretrained(name_or_path)
    except OSError as err:
        cause = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
        save = f"ResNetModel.from_pretrained('{name_or_path}').save_pretrained('resnet-50')"
        raise OSError(
            f"cannot load the pretrained vision encoder {name_or_path!r}: it is not in the Hugging Face "
            f"cache and the Hub cannot be reached (offline?) [{cause}]. Either save it once where there is "
            f'network, `python -c "from transformers import ResNetModel; {save}"`, and pass the folder: '
            "`--model.init_args.resnet_path resnet-50`; or choose a randomly initialised (not pretrained) "
            "encoder explicitly: `--model.init_args.resnet_path null`"
        ) from None


class MusicEncoder(nn.Module):
    """(B, T, music_dim) -> (B, T, Dc).

    The features are standardised per channel with the training set's statistics
    (:meth:`set_statistics`; identity until set) before the projection: the 35 librosa features span five
    orders of magnitude (MFCC 0 about -300 +- 165, the beat and onset-peak one-hots 0 or 1), and raw, the
    projection is all loudness and the beats -- where the dance's phase is -- are drowned.
    """

    def __init__(
        self,
        music_dim: int = NUM_MUSIC_FEATURES,
        dim: int = 256,
        layers: int = 2,
        heads: int = 4,
        ff_dim: int = 512,
        dropout: float = 0.1,
    ):
        super().__init__()
        self.proj = nn.Linear(music_dim, dim)
        self.encoder = transformer_encoder(dim, layers, heads, ff_dim, dropout)
        self.register_buffer("feature_mean", torch.zeros(music_dim))
        self.register_buffer("feature_std", torch.ones(music_dim))

    @torch.no_grad()
    def set_statistics(self, music: torch.Tensor, min_std: float = 1e-3) -> None:
        """Per-channel mean and standard deviation (floored at ``min_std``) of training music (..., L)."""
        expected = self.feature_mean.shape[0]
        if music.shape[-1] != expected:
            raise ValueError(f"music has {music.shape[-1]} features, the encoder {expected}")
        mean, std = channel_statistics(music, min_std=min_std, name="music")
        self.feature_mean.copy_(mean)
        self.feature_std.copy_(std)

    def forward(self, music: torch.Tensor) -> torch.Tensor:
        h = self.proj((music - self.feature_mean.to(music.dtype)) / self.feature_std.to(music.dtype))
        pos = sinusoidal_embedding(torch.arange(music.shape[1], device=music.device), h.shape[-1])
        return self.encoder(h + pos.to(h.dtype))


class VisionEncoder(nn.Module):
    """(B, T, 3, H, W) frames in [0, 1] -> (B, T, Dc).

    Args:
        dim: Dc.
        resnet_path: a pretrained ``transformers`` ResNet: a Hugging Face model id (``microsoft/resnet-50``)
            or a local ``save_pretrained`` folder (:func:`load_resnet`); ``None`` builds ``resnet_config``
            with random weights and warns.
        resnet_config: the architecture when no path is given (default: ResNet-50).
        image_size: frames are resized to (image_size, image_size).
        freeze: keep the ResNet weights fixed (the original code freezes its pretrained ResNet).
        chunk_pixels: pixels per ResNet call, frames x image_size² (bounds memory for long windows): 64
            frames at 224 px; the demo's 600 frames of a batch at 32 px go through in one call, as a
            ResNet over the whole batch would see them. In training mode the ResNet's BatchNorm takes its
            statistics over the frames of one call.
    """

    def __init__(
        self,
        dim: int = 256,
        resnet_path: str | None = None,
        resnet_config: ResNetConfig | None = None,
        image_size: int = 224,
        freeze: bool = True,
        chunk_pixels: int = 64 * 224 * 224,
    ):
        super().__init__()
        if resnet_path is not None:
            self.resnet = load_resnet(resnet_path)
        else:
            warnings.warn(
                "VisionEncoder: no resnet_path given, the ResNet is randomly initialised (not pretrained)",
                RandomWeightsWarning,
                stacklevel=2,
            )
            self.resnet = ResNetModel(resnet_config or ResNetConfig())
        self.freeze = freeze
        if freeze:
            self.resnet.requires_grad_(False)
        self.image_size = image_size
        self.normalize = kornia.enhance.Normalize(torch.tensor(IMAGENET_MEAN), torch.tensor(IMAGENET_STD))
        feat = self.resnet.config.hidden_sizes[-1]
        self.mlp = nn.Sequential(nn.Linear(feat, dim), nn.GELU(), nn.Linear(dim, dim))
        self.chunk = max(1, chunk_pixels // (image_size * image_size))  # frames per ResNet call

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        if frames.ndim != 5 or frames.shape[2] != 3:
            raise ValueError(f"expected frames (B, T, 3, H, W), got {tuple(frames.shape)}")
        b, t = frames.shape[:2]
        flat = frames.flatten(0, 1).float()
        resnet, dtype = self._inference_resnet()
        grad = torch.is_grad_enabled() and not self.freeze
        # Without a backward, channels-last activations: oneDNN's fastest convolution layout on a CPU (the
        # same sums, reordered). With one, contiguous NCHW: oneDNN's convolution backward corrupted the
        # heap on channels-last input (torch 2.13, CPU).
        layout = torch.contiguous_format if grad else torch.channels_last
        feats = []
        for i in range(0, flat.shape[0], self.chunk):
            x = self.normalize(resize_frames(flat[i : i + self.chunk], self.image_size))
            x = x.to(dtype).contiguous(memory_format=layout)
            with torch.set_grad_enabled(grad):
                if resnet is self.resnet:
                    pooled = resnet(pixel_values=x).pooler_output.flatten(1)
                else:
                    with torch.autocast("cpu", enabled=False):
                        pooled = resnet(pixel_values=x).pooler_output.flatten(1).float()
            feats.append(pooled)
        return self.mlp(torch.cat(feats).reshape(b, t, -1))

    def _inference_resnet(self) -> tuple[nn.Module, torch.dtype]:
        """The ResNet to run and its input dtype: under CPU bf16 autocast (``--precision bf16``), a frozen
        ResNet in eval mode runs as a bfloat16 copy of itself (kept, not saved: autocast would cast every
        convolution's weights again at every call, slower than fp32 on a CPU); else the ResNet in fp32."""
        bf16 = torch.is_autocast_enabled("cpu") and torch.get_autocast_dtype("cpu") == torch.bfloat16
        if not (bf16 and self.freeze and not self.training and not self.mlp[0].weight.is_cuda):
            return self.resnet, torch.float32
        # the weights' identity and versions (a load_state_dict bumps them) key the copy
        key = (id(self.resnet), sum(p._version for p in self.resnet.parameters()))
        cached = self.__dict__.get("_bf16_resnet")
        if cached is None or cached[0] != key:  # a plain attribute: not a submodule, not saved
            cached = (key, copy.deepcopy(self.resnet).to(torch.bfloat16).eval())
            self.__dict__["_bf16_resnet"] = cached
        return cached[1], torch.bfloat16


class FusionModule(nn.Module):
    """(B, T, Dc) music and (B, T, Dc) vision -> (B, T, Dc)."""

    def __init__(
        self, dim: int = 256, layers: int = 2, heads: int = 4, ff_dim: int = 512, dropout: float = 0.1
    ):
        super().__init__()
        self.modality = nn.Parameter(torch.randn(2, dim) * 0.02)
        self.encoder = transformer_encoder(dim, layers, heads, ff_dim, dropout)

    def forward(self, music: torch.Tensor, vision: torch.Tensor) -> torch.Tensor:
        t = music.shape[1]
        pos = sinusoidal_embedding(torch.arange(t, device=music.device), music.shape[-1]).to(music.dtype)
        h = torch.cat([music + pos + self.modality[0], vision + pos + self.modality[1]], dim=1)
        h = self.encoder(h)
        return 0.5 * (h[:, :t] + h[:, t:])
