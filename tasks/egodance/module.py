"""LightningModule for EgoMusic dance estimation with EMM (seed 000 sections 6.1-6.2, Table 2).

Training: x0-prediction diffusion (cosine, 1000 steps) on motion tokens, condition dropped with
probability ``cond_drop_prob`` (EDGE: 0.25; learned null condition) for classifier-free guidance,
loss = reconstruction + L_kin (Eq. 29) + lambda_align L_align (the music-vision alignment loss, our
interpretation: :func:`.losses.alignment_loss`), AdamW 2e-4, an exponential moving average of the weights
(original code: 0.995 every 10 steps) used for evaluation and prediction.

Validation logs the diffusion loss at seeded timesteps. Test samples every window (DDIM
``sampling_steps`` or DDPM, guidance weight ``guidance_weight``, head guidance) and reports MPJPE,
root and head errors (mm, FK joints in the canonical frame) and the toolkit's PFC and BeatAlign.
"""

from __future__ import annotations

import torch
from lightning.pytorch import LightningModule
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
from torchmetrics import MeanMetric
from transformers import ResNetConfig

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.backbone_config import backbone_config, plain_backbone_config
from skeleton_mamba.tasks.diffusion import GaussianDiffusion
from skeleton_mamba.tasks.egodance.losses import KinematicLossWeights, alignment_loss, emm_losses
from skeleton_mamba.tasks.egodance.model import EMM
from skeleton_mamba.tasks.egodance.representation import HEAD_JOINT, motion_joints
from skeleton_mamba.tasks.egodance.sampling import sample_dance
from skeleton_mamba.tasks.motion.metrics import PFC, BeatAlign

__all__ = ["EgoDanceModule"]


class EgoDanceModule(LightningModule):
    """EMM trained as a conditional diffusion model.

    Args:
        backbone: SkeletonMamba settings (recipes include ``backbones/skeleton_mamba.yaml``).
        context_dim: Dc (256).
        music_dim: per-frame music features (35 librosa; 4800 Jukebox).
        use_vision: condition on egocentric frames.
        resnet_path: local folder of a pretrained ``transformers`` ResNet (None: random init, warned).
        resnet_layers: ``ResNetConfig`` keyword arguments when no path is given (None: ResNet-50).
        image_size: ResNet input size (match the data module's ``image_size``).
        freeze_resnet: keep the ResNet fixed.
        encoder_layers: music encoder layers (2).
        fusion_layers: fusion module layers (2).
        heads: attention heads of the encoders (4).
        transformer_ff: encoder feed-forward width (512).
        encoder_dropout: encoder dropout.
        diffusion_steps: T (1000).
        cond_drop_prob: probability of training with the null condition.
        reconstruction: ``l2`` (EDGE) or ``l1`` (original code).
        lambda_pos: weight of L_pos. lambda_vel: of L_vel. lambda_contact: of L_contact (unpublished).
        contact_threshold: predicted-contact threshold of L_contact.
        lambda_align: weight of the music-vision alignment loss (0 disables; vision models only).
        align_temperature: its InfoNCE temperature tau.
        lr: AdamW learning rate (2e-4). weight_decay: AdamW weight decay.
        ema_decay: EMA decay. ema_every: update the EMA every this many optimizer steps.
        sampler: ``ddim`` or ``ddpm`` at test/predict time. sampling_steps: DDIM steps.
        guidance_weight: classifier-free guidance weight w (EDGE: 2).
        head_guidance_weight: G_head step size (0 disables). head_guidance_steps: gradient steps per step.
        seed: seed of the evaluation noise.
    """

    def __init__(
        self,
        backbone: SkeletonMambaConfig | None = None,
        context_dim: int = 256,
        music_dim: int = 35,
        use_vision: bool = True,
        resnet_path: str | None = None,
        resnet_layers: dict | None = None,
        image_size: int = 224,
        freeze_resnet: bool = True,
        encoder_layers: int = 2,
        fusion_layers: int = 2,
        heads: int = 4,
        transformer_ff: int = 512,
        encoder_dropout: float = 0.1,
        diffusion_steps: int = 1000,
        cond_drop_prob: float = 0.25,
        reconstruction: str = "l2",
        lambda_pos: float = 1.0,
        lambda_vel: float = 0.1,
        lambda_contact: float = 1.0,
        contact_threshold: float = 0.95,
        lambda_align: float = 0.01,
        align_temperature: float = 0.07,
        lr: float = 2e-4,
        weight_decay: float = 0.02,
        ema_decay: float = 0.995,
        ema_every: int = 10,
        sampler: str = "ddim",
        sampling_steps: int = 50,
        guidance_weight: float = 2.0,
        head_guidance_weight: float = 0.05,
        head_guidance_steps: int = 1,
        seed: int = 0,
    ) -> None:
        super().__init__()
        config = backbone_config(backbone)
        self.save_hyperparameters(ignore=["backbone"])
        self.hparams["backbone"] = plain_backbone_config(config)
        self.model = EMM(
            config,
            context_dim=context_dim,
            music_dim=music_dim,
            use_vision=use_vision,
            resnet_path=resnet_path,
            resnet_config=ResNetConfig(**resnet_layers) if resnet_layers else None,
            image_size=image_size,
            freeze_resnet=freeze_resnet,
            encoder_layers=encoder_layers,
            fusion_layers=fusion_layers,
            heads=heads,
            transformer_ff=transformer_ff,
            dropout=encoder_dropout,
            diffusion_steps=diffusion_steps,
        )
        self.ema = AveragedModel(self.model, multi_avg_fn=get_ema_multi_avg_fn(ema_decay), use_buffers=True)
        self.ema.requires_grad_(False)
        self.diffusion = GaussianDiffusion(diffusion_steps)
        self.weights = KinematicLossWeights(lambda_pos, lambda_vel, lambda_contact)
        self.test_mpjpe, self.test_root, self.test_head = MeanMetric(), MeanMetric(), MeanMetric()
        self.test_pfc = PFC(fps=30.0, up_axis=1)
        self.test_beat_align = BeatAlign(variant="bailando", fps=30.0)

    # ------------------------------------------------------------------ training
    def setup(self, stage: str) -> None:
        """Fit: the denoiser's preconditioning statistics from the training windows' motion."""
        datamodule = getattr(self.trainer, "datamodule", None) if self._trainer is not None else None
        train = (getattr(datamodule, "datasets", None) or {}).get("train")
        if stage == "fit" and train is not None and len(train) > 0:
            self.model.set_data_statistics(torch.stack([item["motion"] for item in train.items]))
            self.ema.module.skip_x0.load_state_dict(self.model.skip_x0.state_dict())

    def _losses(self, batch: dict, generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
        x0 = batch["motion"]
        z_a, z_v = self.model.encode_modalities(batch["music"], batch.get("frames"))
        context = self.model.fuse(z_a, z_v)
        b = x0.shape[0]
        u = torch.rand(b, generator=generator).to(x0.device)
        context = self.model.drop_condition(context, u < self.hparams.cond_drop_prob)
        t = torch.randint(0, self.diffusion.num_steps, (b,), generator=generator).to(x0.device)
        noise = torch.randn(x0.shape, generator=generator).to(x0.device, x0.dtype)
        x_t, t, target = self.diffusion.training_pair(x0, t, noise)
        losses = emm_losses(
            self.model(x_t, t, context),
            target,
            self.weights,
            self.hparams.reconstruction,
            self.hparams.contact_threshold,
        )
        if z_v is not None and self.hparams.lambda_align > 0:
            losses["align"] = alignment_loss(z_a, z_v, self.hparams.align_temperature)
            losses["loss"] = losses["loss"] + self.hparams.lambda_align * losses["align"]
        return losses

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        losses = self._losses(batch)
        b = batch["motion"].shape[0]
        self.log_dict({f"train/{k}": v for k, v in losses.items() if k != "loss"}, batch_size=b)
        self.log("train/loss", losses["loss"], prog_bar=True, batch_size=b)
        return losses["loss"]

    def on_train_batch_end(self, outputs, batch, batch_idx: int) -> None:
        if self.global_step % self.hparams.ema_every == 0:
            self.ema.update_parameters(self.model)

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        gen = torch.Generator().manual_seed(self.hparams.seed + batch_idx)
        losses = self._losses(batch, gen)
        self.log(
            "val/loss", losses["loss"], prog_bar=True, batch_size=batch["motion"].shape[0], sync_dist=True
        )

    # ------------------------------------------------------------------ sampling
    def sample(self, batch: dict, batch_idx: int = 0, use_ema: bool = True) -> torch.Tensor:
        """Motion tokens (B, T, 24, 10) for a batch's music, frames and head targets."""
        model = self.ema.module if use_ema else self.model
        hp = self.hparams
        return sample_dance(
            model,
            self.diffusion,
            batch["music"],
            batch.get("frames"),
            batch.get("head"),
            sampler=hp.sampler,
            steps=hp.sampling_steps,
            guidance_weight=hp.guidance_weight,
            head_weight=hp.head_guidance_weight,
            head_steps=hp.head_guidance_steps,
            generator=torch.Generator().manual_seed(hp.seed + batch_idx),
        )

    def test_step(self, batch: dict, batch_idx: int) -> None:
        pred = motion_joints(self.sample(batch, batch_idx))
        true = motion_joints(batch["motion"])
        err = (pred - true).norm(dim=-1) * 1000.0  # (B, T, 24) mm
        b = pred.shape[0]
        self.test_mpjpe.update(err.mean(dim=(1, 2)))
        self.test_root.update(err[..., 0].mean(dim=1))
        self.test_head.update(err[..., HEAD_JOINT].mean(dim=1))
        self.test_pfc.update(pred.float().cpu())
        self.test_beat_align.update(pred.float().cpu(), batch["music"][..., 34].cpu())
        metrics = {
            "test/mpjpe_mm": self.test_mpjpe,
            "test/root_error_mm": self.test_root,
            "test/head_error_mm": self.test_head,
            "test/pfc": self.test_pfc,
            "test/beat_align": self.test_beat_align,
        }
        self.log_dict(metrics, batch_size=b)

    def predict_step(self, batch: dict, batch_idx: int) -> dict:
        """``sample_id``, ``tokens`` (B, T, 24, 10) and FK ``joints`` (B, T, 24, 3) of sampled dances."""
        tokens = self.sample(batch, batch_idx)
        return {"sample_id": batch.get("sample_id"), "tokens": tokens, "joints": motion_joints(tokens)}

    def configure_optimizers(self):
        params = [p for p in self.model.parameters() if p.requires_grad]
        return torch.optim.AdamW(params, lr=self.hparams.lr, weight_decay=self.hparams.weight_decay)
