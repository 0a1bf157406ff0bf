"""EMM, the EgoMusic Motion network ([EgoMusic] supp. Tables 1-2, Sec. 6.2): a conditional x0 denoiser.

::

    music (B, T, L) -> MusicEncoder -> (B, T, Dc) --+
                                                     +-> FusionModule -> c (B, T, Dc)
    frames (B, T, 3, H, W) -> VisionEncoder -> ...--+
    x_t (B, T, 24, 10) -> c_in -> Linear -> + time embedding -> SkeletonMamba(N blocks, cross-attention
        to [time token; c]) -> Linear -> F -> x0_hat = mu + c_skip (x_t - a mu) + c_out F (B, T, 24, 10)
        [-> Gaussian low-pass over T, ``output_smoothing`` > 0 only]

(the preconditioning with the training data's per-channel mean and standard deviation, set by
:meth:`EMM.set_data_statistics`: :mod:`skeleton_mamba.tasks.training.diffusion.parameterisation`)

``forward(x_t, t, context)`` is a denoiser for :mod:`skeleton_mamba.tasks.training.diffusion`
(``context=None``: the learned null condition, for classifier-free guidance). Defaults are [EgoMusic]'s:
D 128, Dc 256, G 5, P 6, E 768, N 8, 4 heads, MLP 1024, Transformer feed-forward 512.
"""

from __future__ import annotations

import dataclasses
import math

import torch
from torch import nn
from transformers import ResNetConfig

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.errors import RandomWeightsWarning
from skeleton_mamba.pretrained.mixin import PretrainedMixin
from skeleton_mamba.tasks.egodance.encoders import FusionModule, MusicEncoder, VisionEncoder
from skeleton_mamba.tasks.egodance.heading_frames import head_rotation, relative_headings
from skeleton_mamba.tasks.egodance.representation import NUM_CHANNELS, NUM_JOINTS
from skeleton_mamba.tasks.motion.body.statistics import channel_statistics
from skeleton_mamba.tasks.motion.body.temporal_filter import smooth_over_time
from skeleton_mamba.tasks.motion.music.features import NUM_MUSIC_FEATURES
from skeleton_mamba.tasks.training.backbone_config import derived_backbone
from skeleton_mamba.tasks.training.diffusion.embedding import sinusoidal_embedding
from skeleton_mamba.tasks.training.diffusion.parameterisation import SkipX0

__all__ = ["EMM", "EMMConfig"]


@dataclasses.dataclass
class EMMConfig:
    """EMM's condition encoders ([EgoMusic] supp. Table 2; the backbone is a :class:`SkeletonMambaConfig`).

    Attributes:
        context_dim: Dc, the width of the condition tokens (256).
        music_dim: L, per-frame music features (35: librosa; 4800: Jukebox).
        use_vision: encode egocentric frames (``False``: music-only condition).
        resnet_layers: ``ResNetConfig`` keyword arguments of a ResNet built without ``resnet_path`` (None:
            ResNet-50).
        freeze_resnet: keep the ResNet fixed.
        encoder_layers: Transformer layers of the music encoder (2).
        fusion_layers: Transformer layers of the fusion module (2).
        heads: attention heads of the encoders (4).
        transformer_ff: feed-forward width of the encoders ("Transformer dim" 512).
        dropout: dropout of the encoders.
        frame_condition: also add the condition of frame t, projected to the backbone width, to the pose
            embedding of frame t (ours; off in [EgoMusic]). The table's cross-attention reaches the
            condition only after a block's scans, and its queries carry no frame position, so a shallow
            backbone must learn to align frame t with condition t before the music can set the pose: the
            demo's one-block EMM, 200 steps, reached the same x0 error with and without the condition.
            Added per frame, the condition is aligned by construction and the Temporal Scan sees the beats.
        output_smoothing: sigma (frames) of a Gaussian low-pass over time applied to the denoiser's x0
            (:func:`~skeleton_mamba.tasks.motion.body.temporal_filter.smooth_over_time`), in training and
            sampling alike (ours; 0: off, [EgoMusic]). A network trained for a few hundred steps has not
            learned that dance is smooth: its x0 carries 4-15 Hz frame-to-frame trembling, from the noise
            of x_t passed on by the skip connection and from the per-frame condition. The filter makes every
            x0 it can predict band-limited (sigma 2 at 30 fps: 70 % of a 2 Hz swing, 11 % of 5 Hz, nothing
            of 10 Hz), and training sees the filtered x0, so the network learns to drive it to the data.
            Sharp real dance has content above that band: leave it off for long training on real data.
        heading_condition: also condition on the head's turns within the window, given as (B, T) radians
            since the window's first frame, taken about their mean over the window (so a swing reads the same
            wherever the window starts in it), scaled by the training turns' spread, embedded and added to
            every frame's condition token (ours; off in [EgoMusic]). The egocentric video shows them
            (:mod:`.video_rotation` reads them at inference; training reads the camera path's), but a small
            vision encoder trained from scratch on single frames does not learn to compare frames: the
            demo's dancers turn with the side of their swing, and without the turns the demo's EMM swung its
            arms to the wrong side on whole songs.
    """

    context_dim: int = 256
    music_dim: int = NUM_MUSIC_FEATURES
    use_vision: bool = True
    resnet_layers: dict | None = None
    freeze_resnet: bool = True
    encoder_layers: int = 2
    fusion_layers: int = 2
    heads: int = 4
    transformer_ff: int = 512
    dropout: float = 0.1
    frame_condition: bool = False
    output_smoothing: float = 0.0
    heading_condition: bool = False

    def __post_init__(self) -> None:
        if not (self.output_smoothing >= 0 and math.isfinite(self.output_smoothing)):
            raise ValueError(f"output_smoothing must be >= 0 frames, got {self.output_smoothing}")


class EMM(PretrainedMixin, nn.Module):
    """The EgoMusic Motion network.

    Args:
        backbone: the SkeletonMamba settings; its skeleton, channels and ``context_dim`` are EMM's (the last
            ``config.context_dim``): a backbone that sets them otherwise is refused, not overwritten.
        config: the condition encoders' settings (None: :class:`EMMConfig` defaults).
        resnet_path: the pretrained ``transformers`` ResNet: a Hugging Face model id (``microsoft/resnet-50``,
            downloaded once and cached) or a local ``save_pretrained`` folder; None: random init of
            ``config.resnet_layers`` (an explicit choice, warned).
        image_size: square size the frames are resized to (the ResNet input).
        diffusion_steps: T of the noise schedule (of the preconditioning's scalings).

    ``save_pretrained`` / ``from_pretrained``: :mod:`skeleton_mamba.pretrained.mixin` (the ResNet's weights
    are in the folder, its architecture in ``config.resnet_layers``).
    """

    pretrained_task = (
        "EgoMusic Motion network (EMM): x0 denoiser of SMPL-24 dance from music and egocentric video."
    )
    pretrained_citations = ("EgoMusic", "Mamba-2", "EDGE")
    pretrained_ignored_warnings = (RandomWeightsWarning,)

    def __init__(
        self,
        backbone: SkeletonMambaConfig | None = None,
        config: EMMConfig | None = None,
        resnet_path: str | None = None,
        image_size: int = 224,
        diffusion_steps: int = 1000,
    ):
        super().__init__()
        self.config = c = config or EMMConfig()
        context_dim = c.context_dim
        cfg = derived_backbone(  # context_dim: network.context_dim, the one place it is set
            backbone,
            "EMM",
            skeleton="smpl24",
            in_channels=None,
            out_channels=NUM_CHANNELS,
            context_dim=context_dim,
        )
        self.dim = d = cfg.dim
        self.context_dim = context_dim
        self.input_proj = nn.Linear(NUM_CHANNELS, d)
        self.time_mlp = nn.Sequential(nn.Linear(d, 4 * d), nn.SiLU(), nn.Linear(4 * d, d))
        self.time_token = nn.Linear(d, context_dim)
        self.backbone = SkeletonMamba(cfg)
        self.music_encoder = MusicEncoder(
            c.music_dim, context_dim, c.encoder_layers, c.heads, c.transformer_ff, c.dropout
        )
        resnet_config = ResNetConfig(**c.resnet_layers) if c.resnet_layers else None
        self.vision_encoder = (
            VisionEncoder(context_dim, resnet_path, resnet_config, image_size, c.freeze_resnet)
            if c.use_vision
            else None
        )
        self.fusion = (
            FusionModule(context_dim, c.fusion_layers, c.heads, c.transformer_ff, c.dropout)
            if c.use_vision
            else None
        )
        self.null_context = nn.Parameter(torch.randn(1, 1, context_dim) * 0.02)
        self.heading_embedding = nn.Linear(2, context_dim) if c.heading_condition else None
        if c.heading_condition:  # the training turns' spread (set_data_statistics), as the music's
            self.register_buffer("heading_scale", torch.ones(()))
        self.frame_condition = nn.Linear(context_dim, d) if c.frame_condition else None
        self.skip_x0 = SkipX0(diffusion_steps, channels=(NUM_JOINTS, NUM_CHANNELS))

    def pretrained_init_args(self) -> dict:
        """As built, but the ResNet from its architecture (``resnet_layers``) instead of ``resnet_path``: the
        folder's weights replace it, so loading reads no other file."""
        args = super().pretrained_init_args()
        if self.vision_encoder is not None:
            resnet = self.vision_encoder.resnet.config
            layers = ("num_channels", "embedding_size", "hidden_sizes", "depths", "layer_type", "hidden_act")
            layers += ("downsample_in_first_stage", "downsample_in_bottleneck")
            resnet_layers = {k: getattr(resnet, k) for k in layers if hasattr(resnet, k)}
            args.update(
                config=dataclasses.replace(self.config, resnet_layers=resnet_layers), resnet_path=None
            )
        return args

    def set_data_statistics(self, motion: torch.Tensor, music: torch.Tensor | None = None) -> None:
        """Per-channel mean and standard deviation of training motion tokens (N, T, 24, 10) (the
        preconditioning) and of their music features (N, T, L) (the music encoder's standardisation)."""
        tokens = motion.reshape(-1, NUM_JOINTS, NUM_CHANNELS)
        self.skip_x0.set_statistics(*channel_statistics(tokens, channel_dims=2, name="motion"))
        if self.heading_embedding is not None:  # the head's turns in the training windows, from their motion
            turns = relative_headings(head_rotation(motion.double()))
            turns = turns - turns.mean(-1, keepdim=True)
            self.heading_scale.fill_(float(turns.sin().std().clamp_min(1e-3)))
        if music is not None:
            self.music_encoder.set_statistics(music)

    def encode_modalities(
        self, music: torch.Tensor, frames: torch.Tensor | None = None, vision: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Music (B, T, L), frames (B, T, 3, H, W) in [0, 1] -> z_a (B, T, Dc), z_v (B, T, Dc) or None.

        ``vision``: instead of ``frames``, their z_v (B, T, Dc) already computed (the vision encoder is per
        frame: :func:`~skeleton_mamba.tasks.egodance.video_features.encode_video` streams a long video).
        """
        if vision is not None:
            if frames is not None:
                raise ValueError("give frames or their vision features, not both")
            if self.vision_encoder is None:
                raise ValueError("this EMM is music-only (use_vision=False) but vision features were given")
            if vision.shape[:2] != music.shape[:2] or vision.shape[-1] != self.context_dim:
                raise ValueError(
                    f"vision features {tuple(vision.shape)} do not fit music {tuple(music.shape[:2])} and "
                    f"Dc = {self.context_dim}"
                )
        z_a = self.music_encoder(music)
        if vision is not None or self.vision_encoder is None:
            return z_a, vision
        if frames is None:
            raise ValueError("this EMM encodes egocentric frames (use_vision=True) but none were given")
        if frames.shape[:2] != music.shape[:2]:
            raise ValueError(
                f"frames {tuple(frames.shape[:2])} and music {tuple(music.shape[:2])} disagree on (B, T)"
            )
        return z_a, self.vision_encoder(frames)

    def fuse(
        self, z_a: torch.Tensor, z_v: torch.Tensor | None, heading: torch.Tensor | None = None
    ) -> torch.Tensor:
        """The fusion module (music only: z_a unchanged) -> condition c (B, T, Dc); a model with
        ``heading_condition`` adds the embedded head turns ``heading`` (B, T) (radians since frame 0)."""
        context = z_a if z_v is None else self.fusion(z_a, z_v)
        if self.heading_embedding is None:
            if heading is not None:
                raise ValueError("this EMM was not trained on the head's turns (heading_condition=False)")
            return context
        if heading is None:
            raise ValueError(
                "this EMM reads the head's turns within each window (heading_condition=True): give heading "
                "(B, T) radians since the window's first frame, read from the egocentric video or the camera "
                "path"
            )
        if heading.shape != context.shape[:2]:
            raise ValueError(
                f"heading {tuple(heading.shape)} does not fit the condition {tuple(context.shape[:2])}"
            )
        return context + self.heading_embedding(self.heading_features(heading.to(context.dtype)))

    def heading_features(self, heading: torch.Tensor) -> torch.Tensor:
        """Turns (B, T) since each window's first frame -> (B, T, 2) ``(sin h, 1 - cos h) / s`` of the turns
        ``h`` about their window mean (the same swing wherever the window starts in it), ``s`` the training
        turns' standard deviation of ``sin h`` (a swing of a few degrees reads as large as the music does;
        continuous through a whole spin)."""
        heading = heading - heading.mean(1, keepdim=True)
        return torch.stack([heading.sin(), 1 - heading.cos()], -1) / self.heading_scale.to(heading.dtype)

    def encode_condition(
        self,
        music: torch.Tensor,
        frames: torch.Tensor | None = None,
        vision: torch.Tensor | None = None,
        heading: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Music (B, T, L) and frames (B, T, 3, H, W) in [0, 1] (or their z_v ``vision`` (B, T, Dc)), and for
        a model with ``heading_condition`` the head's turns ``heading`` (B, T) -> fused condition c
        (B, T, Dc)."""
        return self.fuse(*self.encode_modalities(music, frames, vision), heading)

    def null_condition(self, context: torch.Tensor) -> torch.Tensor:
        """The learned null condition shaped like ``context`` (B, S, Dc)
        (:class:`~skeleton_mamba.tasks.training.diffusion.NullConditioned`: guidance in one call)."""
        return self.null_context.to(context.dtype).expand_as(context)

    def drop_condition(self, context: torch.Tensor, drop: torch.Tensor) -> torch.Tensor:
        """Replace the condition of samples where ``drop`` (B,) is True by the learned null condition."""
        return torch.where(drop[:, None, None], self.null_condition(context), context)

    def forward(
        self,
        x_t: torch.Tensor,
        t: torch.Tensor,
        context: torch.Tensor | None = None,
        mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Predict x0.

        Args:
            x_t: (B, T, 24, 10) noisy motion tokens.
            t: (B,) long diffusion timesteps.
            context: (B, S, Dc) condition tokens, or None for the null condition.
            mask: (B, T) bool valid frames (right padding).

        Returns:
            x0_hat (B, T, 24, 10).
        """
        b, n = x_t.shape[:2]
        if context is None:
            context = self.null_context.to(x_t.dtype).expand(b, n, -1)
        # the [sin, cos] timestep embedding (EDGE's order; diffusion/embedding.py)
        temb = self.time_mlp(sinusoidal_embedding(t, self.dim).to(x_t.dtype))
        h = self.input_proj(self.skip_x0.network_input(x_t, t)) + temb[:, None, None, :]
        if self.frame_condition is not None:
            if context.shape[1] != n:
                raise ValueError(
                    f"frame_condition needs one condition token per frame: {context.shape[1]} for {n} frames"
                )
            h = h + self.frame_condition(context)[:, :, None, :]
        context = torch.cat([self.time_token(temb)[:, None], context], dim=1)
        x0 = self.skip_x0(x_t, self.backbone(h, mask=mask, context=context), t)
        if self.config.output_smoothing > 0:
            x0 = smooth_over_time(x0, self.config.output_smoothing, mask)
        return x0
