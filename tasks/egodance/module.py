"""LightningModule for EgoMusic dance estimation with EMM ([EgoMusic] supp. sections 6.1-6.2, Table 2).

Training: x0-prediction diffusion (cosine, 1000 steps) on motion tokens, condition dropped with
probability ``cond_drop_prob`` (EDGE: 0.25; learned null condition; 0 in the paper's protocol) for
classifier-free guidance, loss = reconstruction + L_kin ([EgoMusic] supp. Eq. 29) + lambda_align L_align
(the music-vision alignment loss, our interpretation: :func:`.losses.alignment_loss`), AdamW 2e-4, an
exponential moving average of the weights (original code: 0.995 every 10 steps) used for evaluation and
prediction. Vision models also train the head-trajectory estimator (:mod:`.head_estimator`, ours: its own
parameters, loss ``train/head_traj`` and gradient clipping, so the EMM's training is unchanged).

Head guidance takes its targets from ``head_source``: ``estimate`` (the default: the estimator on the
egocentric frames, what a user's video allows), ``oracle`` (the ground-truth camera path of EgoAIST++,
reported as such) or ``none``. Validation logs the diffusion loss at seeded timesteps. Test samples every
window (DDPM, or DDIM ``sampling_steps``; classifier-free guidance weight ``guidance_weight``) once per
head source -- ``head_source`` and, with ``test_oracle_head``, the oracle too, from the same noise -- and
logs for each ``test/<estimated|oracle>_head/``: MPJPE, root and head errors (mm, FK joints in the
canonical frame) and MMV ([EgoMusic] supp. 7.1, with its MM and MV terms), and, under the named
dance-evaluation ``protocol`` (:mod:`~skeleton_mamba.tasks.motion.metrics.protocols`; default ``"edge"``:
5 s windows at 30 fps, EDGE's per-slice music beats, PFC), BeatAlign, PFC and, over the epoch, FID_k / FID_g /
Div_k / Div_g of the sampled windows against the ground-truth windows (with at least 2 windows); plus the
estimator's own errors ``test/head_estimator/{position_mm, rotation_deg}``. The protocol's music beats come
from each window's music file (``music_path``, ``music_start_s`` of the batch, which the data module
provides) by the protocol's own recipe; ``"fact"`` here has no seed (frame 0 on). ``sm predict`` samples the
test windows and writes each dance as files (:mod:`.prediction_writer`).
"""

from __future__ import annotations

import dataclasses

import torch
from lightning.pytorch.utilities import rank_zero_info
from torch import nn
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
from torchmetrics import MeanMetric

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.egodance.evaluation import DanceMetrics, video_beats
from skeleton_mamba.tasks.egodance.head_estimator import (
    HeadEstimatorConfig,
    HeadTrajectoryEstimator,
    head_trajectory_errors,
    head_trajectory_loss,
)
from skeleton_mamba.tasks.egodance.heading_frames import relative_headings
from skeleton_mamba.tasks.egodance.long_form import LongForm, head_targets
from skeleton_mamba.tasks.egodance.losses import KinematicLossWeights, alignment_loss, emm_losses
from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
from skeleton_mamba.tasks.egodance.prediction_writer import DancePredictionWriter
from skeleton_mamba.tasks.egodance.representation import FPS, motion_joints
from skeleton_mamba.tasks.egodance.sampling import sample_dance, sample_long_dance
from skeleton_mamba.tasks.motion.metrics.evaluation import DanceEvaluation
from skeleton_mamba.tasks.motion.metrics.protocols import PROTOCOLS, FACTProtocol, get_protocol
from skeleton_mamba.tasks.motion.music.features import record_audio_stack
from skeleton_mamba.tasks.training.backbone_config import config_from, plain_backbone_config
from skeleton_mamba.tasks.training.base_module import BackboneModule
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, SamplingOptions

__all__ = ["EgoDanceModule", "HEAD_SOURCES"]

HEAD_SOURCES = {"estimate": "estimated_head", "oracle": "oracle_head", "none": "unguided"}
"""Head-guidance sources and the name their test metrics are logged under (``test/<name>/...``)."""


@dataclasses.dataclass(frozen=True)
class DanceSampling(SamplingOptions):
    """The EMM's test and predict sampling (:class:`SamplingOptions`); classifier-free guidance w 2 (EDGE)."""

    guidance_weight: float = 2.0


@dataclasses.dataclass(frozen=True)
class LossOptions:
    """The training loss beside L_kin's weights (:class:`~.losses.KinematicLossWeights`).

    Attributes:
        cond_drop_prob: probability of training with the null condition (EDGE: 0.25).
        reconstruction: ``l2`` (EDGE) or ``l1`` (original code).
        contact_threshold: predicted-contact threshold of L_contact.
        lambda_align: weight of the music-vision alignment loss (0 disables; vision models only).
        align_temperature: its InfoNCE temperature tau.
        lambda_head: weight of the head-trajectory estimator's loss.
    """

    cond_drop_prob: float = 0.25
    reconstruction: str = "l2"
    contact_threshold: float = 0.95
    lambda_align: float = 0.01
    align_temperature: float = 0.07
    lambda_head: float = 1.0


@dataclasses.dataclass(frozen=True)
class OptimizerOptions:
    """AdamW and the weights' exponential moving average (original code: 0.995 every 10 steps).

    Attributes:
        lr: AdamW learning rate (2e-4). weight_decay: AdamW weight decay.
        ema_decay: EMA decay. ema_every: update the EMA every this many optimizer steps.
    """

    lr: float = 2e-4
    weight_decay: float = 0.02
    ema_decay: float = 0.995
    ema_every: int = 10


@dataclasses.dataclass(frozen=True)
class HeadGuidance:
    """G_head at sampling time.

    Attributes:
        weight: step size (0 disables). steps: gradient steps per sampling step.
        source: where it takes its targets (:data:`HEAD_SOURCES`): ``estimate`` (from the frames), ``oracle``
            (the ground-truth camera path; evaluation only) or ``none``.
        test_oracle: at test, also sample with the oracle head (logged as ``test/oracle_head/...``).
    """

    weight: float = 0.05
    steps: int = 1
    source: str = "estimate"
    test_oracle: bool = True


@dataclasses.dataclass(frozen=True)
class EvaluationOptions:
    """Validation and test.

    Attributes:
        seed: seed of the evaluation noise.
        protocol: dance-evaluation protocol of the test loop: ``"edge"`` (default), ``"bailando"`` or
            ``"fact"`` (see the module docstring).
    """

    seed: int = 0
    protocol: str = "edge"


_GROUPS = ("loss", "kinematic", "optimizer", "sampling", "head_guidance", "head_estimator", "evaluation")
"""EgoDanceModule's arguments that are config dataclasses (stored in checkpoints as plain dicts)."""


class EgoDanceModule(BackboneModule):
    """EMM trained as a conditional diffusion model.

    Every group of settings is a config dataclass passed whole; its defaults are the dataclass's and
    checkpoints store it as a plain dict.

    Args:
        backbone: SkeletonMamba settings (recipes include ``backbones/skeleton_mamba.yaml``).
        network: the condition encoders' settings (:class:`~.model.EMMConfig`; None: its defaults).
        resnet_path: the pretrained ``transformers`` ResNet: a Hugging Face model id (``microsoft/resnet-50``,
            downloaded once and cached) or a local ``save_pretrained`` folder; None: random init of
            ``network.resnet_layers`` (an explicit choice, warned).
        image_size: ResNet input size. Linked from the data module (not user-settable under ``sm``).
        fps: motion and music frame rate of the test metrics. Linked from the data module (its default
            :data:`.representation.FPS` when the module is built alone).
        window: the training window (frames). Linked from the data module: longer test and predict
            sequences are danced long-form in windows of this length (:func:`.sampling.sample_long_dance`).
        canonicalize_init_head: the data's windows face their first frame's head heading. Linked from the
            data module: long-form windows are then sampled each in that frame (:mod:`.heading_frames`).
        inpaint_overlaps: long-form windows in-paint the overlap they share with the window before at every
            denoising step ([EDGE]); False: each window is sampled from its own conditions and the windows
            are joined by the cross-fade (:func:`.sampling.sample_long_dance`; the demo's choice, measured in
            its tutorial).
        diffusion_steps: T (1000).
        loss: :class:`LossOptions`. kinematic: L_kin's weights (:class:`~.losses.KinematicLossWeights`).
        optimizer: :class:`OptimizerOptions`.
        sampling: sampler at test/predict time (:class:`DanceSampling`).
        head_guidance: :class:`HeadGuidance`.
        use_head_estimator: train the head-trajectory estimator (vision models only).
        head_estimator: its settings (:class:`~.head_estimator.HeadEstimatorConfig`).
        evaluation: :class:`EvaluationOptions`.
    """

    # Dataclass defaults (never mutated) so that LightningCLI shows and sets every field of each group.
    def __init__(
        self,
        backbone: SkeletonMambaConfig | None = None,
        network: EMMConfig | None = None,
        resnet_path: str | None = None,
        image_size: int = 224,
        fps: int = FPS,
        window: int = 150,
        canonicalize_init_head: bool = False,
        inpaint_overlaps: bool = True,
        diffusion_steps: int = 1000,
        loss: LossOptions = LossOptions(),  # noqa: B008
        kinematic: KinematicLossWeights = KinematicLossWeights(),  # noqa: B008
        optimizer: OptimizerOptions = OptimizerOptions(),  # noqa: B008
        sampling: DanceSampling = DanceSampling(),  # noqa: B008
        head_guidance: HeadGuidance = HeadGuidance(),  # noqa: B008
        use_head_estimator: bool = True,
        head_estimator: HeadEstimatorConfig = HeadEstimatorConfig(),  # noqa: B008
        evaluation: EvaluationOptions = EvaluationOptions(),  # noqa: B008
    ) -> None:
        super().__init__()
        network = config_from(EMMConfig, network)
        self.loss_options = config_from(LossOptions, loss)
        self.weights = config_from(KinematicLossWeights, kinematic)
        self.optimizer_options = config_from(OptimizerOptions, optimizer)
        self.sampling = config_from(DanceSampling, sampling)
        self.sampling.check_steps(diffusion_steps)  # the step count against T, when the module is made
        self.head_guidance = config_from(HeadGuidance, head_guidance)
        estimator_config = config_from(HeadEstimatorConfig, head_estimator)
        self.evaluation = config_from(EvaluationOptions, evaluation)
        protocol = self.evaluation.protocol
        if protocol not in PROTOCOLS:
            raise ValueError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
        source = self.head_guidance.source
        if source not in HEAD_SOURCES:
            raise ValueError(f"head_source must be one of {sorted(HEAD_SOURCES)}, got {source!r}")
        has_estimator = network.use_vision and use_head_estimator
        if source == "estimate" and not has_estimator:
            raise ValueError(
                "head_source='estimate' needs the head-trajectory estimator, which needs egocentric frames "
                "(use_vision=True, use_head_estimator=True); choose head_source 'none' (or 'oracle')"
            )
        config = self.save_backbone_hyperparameters(backbone, ignore=("network", *_GROUPS))
        self.hparams["network"] = plain_backbone_config(network)
        groups = (self.loss_options, self.weights, self.optimizer_options, self.sampling, self.head_guidance,
                  estimator_config, self.evaluation)  # fmt: skip
        self.hparams.update({name: plain_backbone_config(group) for name, group in zip(_GROUPS, groups)})
        self.model = EMM(config, network, resnet_path, image_size, diffusion_steps)
        ema = get_ema_multi_avg_fn(self.optimizer_options.ema_decay)
        self.ema = AveragedModel(self.model, multi_avg_fn=ema, use_buffers=True)
        self.ema.requires_grad_(False)
        self.diffusion = GaussianDiffusion(diffusion_steps)
        self.head_estimator = HeadTrajectoryEstimator(estimator_config) if has_estimator else None
        self.test_metrics = nn.ModuleDict({name: DanceMetrics() for name in HEAD_SOURCES.values()})
        scorer = FACTProtocol(seed_frames=0) if protocol == "fact" else get_protocol(protocol)
        self.test_evaluations = nn.ModuleDict(
            {name: DanceEvaluation(scorer) for name in HEAD_SOURCES.values()}
        )
        self.test_head_position, self.test_head_rotation = MeanMetric(), MeanMetric()

    def parameter_counts(self) -> dict[str, int]:
        """Parameters of the EMM (trainable / frozen) and of the head estimator (the EMA copy not counted)."""
        counts = {"emm_trainable": 0, "emm_frozen": 0, "head_estimator": 0}
        for p in self.model.parameters():
            counts["emm_trainable" if p.requires_grad else "emm_frozen"] += p.numel()
        if self.head_estimator is not None:
            counts["head_estimator"] = sum(p.numel() for p in self.head_estimator.parameters())
        return counts

    def on_fit_start(self) -> None:
        c = {k: v / 1e6 for k, v in self.parameter_counts().items()}
        rank_zero_info(
            f"EMM parameters: {c['emm_trainable']:.1f} M trainable + {c['emm_frozen']:.1f} M frozen "
            f"(ResNet) = {c['emm_trainable'] + c['emm_frozen']:.1f} M ([EgoMusic] supp. Table 3: 47.4 M); "
            f"head-trajectory estimator (ours): {c['head_estimator']:.2f} M; the EMA copy is not counted"
        )

    # ------------------------------------------------------------------ training
    def set_data_statistics(self, statistics) -> None:
        """The denoiser's preconditioning statistics from the training windows' ``motion``, and the music
        encoder's from their ``music`` (:class:`.data.EgoDanceStatistics`)."""
        for model in (self.model, self.ema.module):
            model.set_data_statistics(statistics.motion, statistics.music)

    @staticmethod
    def condition_heading(model: EMM, batch: dict, index: int | None = None) -> torch.Tensor | None:
        """The head's turns since each sequence's first frame, (B, T) radians (or (T,) of sequence ``index``),
        from the batch's camera path (``head_rotation``), for a model with ``heading_condition``; else
        None."""
        if model.heading_embedding is None:
            return None
        if batch.get("head_rotation") is None:
            raise ValueError(
                "this EMM reads the head's turns (heading_condition=True): the batch needs the camera path's "
                "head rotations (head_rotation, from the sample's camera.npz)"
            )
        rotation = batch["head_rotation"] if index is None else batch["head_rotation"][index]
        return relative_headings(rotation.to(batch["music"].dtype))

    def _losses(self, batch: dict, generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
        x0 = batch["motion"]
        z_a, z_v = self.model.encode_modalities(batch["music"], batch.get("frames"))
        context = self.model.fuse(z_a, z_v, self.condition_heading(self.model, batch))
        b = x0.shape[0]
        u = torch.rand(b, generator=generator).to(x0.device)
        context = self.model.drop_condition(context, u < self.loss_options.cond_drop_prob)
        t = torch.randint(0, self.diffusion.num_steps, (b,), generator=generator).to(x0.device)
        noise = torch.randn(x0.shape, generator=generator).to(x0.device, x0.dtype)
        x_t, t, target = self.diffusion.training_pair(x0, t, noise)
        losses = emm_losses(
            self.model(x_t, t, context),
            target,
            self.weights,
            self.loss_options.reconstruction,
            self.loss_options.contact_threshold,
        )
        if z_v is not None and self.loss_options.lambda_align > 0:
            losses["align"] = alignment_loss(z_a, z_v, self.loss_options.align_temperature)
            losses["loss"] = losses["loss"] + self.loss_options.lambda_align * losses["align"]
        return losses

    def _head_estimator_loss(self, batch: dict) -> torch.Tensor | None:
        """The estimator's loss on the batch's ground-truth head path (None without estimator or path)."""
        if self.head_estimator is None or "head_rotation" not in batch or batch.get("frames") is None:
            return None
        positions, rotations = self.head_estimator(batch["frames"])
        return head_trajectory_loss(
            positions,
            rotations,
            batch["head"],
            batch["head_rotation"],
            self.head_estimator.config.rotation_weight,
            self.head_estimator.config.position_scale,
        )

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        losses = self._losses(batch)
        head_loss = self._head_estimator_loss(batch)
        if head_loss is not None:  # independent parameters: adding it leaves the EMM's gradients unchanged
            losses["head_traj"] = head_loss
            losses["loss"] = losses["loss"] + self.loss_options.lambda_head * head_loss
        b = batch["motion"].shape[0]
        self.log_dict({f"train/{k}": v for k, v in losses.items() if k != "loss"}, batch_size=b)
        self.log("train/loss", losses["loss"], prog_bar=True, batch_size=b)
        return losses["loss"]

    def on_train_batch_end(self, outputs, batch, batch_idx: int) -> None:
        if self.global_step % self.optimizer_options.ema_every == 0:
            self.ema.update_parameters(self.model)

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        gen = torch.Generator().manual_seed(self.evaluation.seed + batch_idx)
        losses = self._losses(batch, gen)
        b = batch["motion"].shape[0]
        self.log("val/loss", losses["loss"], prog_bar=True, batch_size=b, sync_dist=True)
        head_loss = self._head_estimator_loss(batch)
        if head_loss is not None:
            self.log("val/head_traj", head_loss, batch_size=b, sync_dist=True)

    def configure_gradient_clipping(self, optimizer, gradient_clip_val=None, gradient_clip_algorithm=None):
        """Clip the EMM and the head estimator separately, so the estimator never rescales the EMM's step."""
        if not gradient_clip_val:
            return
        groups = [self.model.parameters()]
        if self.head_estimator is not None:
            groups.append(self.head_estimator.parameters())
        for params in groups:
            grads = [p for p in params if p.grad is not None]
            if gradient_clip_algorithm == "value":
                nn.utils.clip_grad_value_(grads, gradient_clip_val)
            else:
                nn.utils.clip_grad_norm_(grads, gradient_clip_val)

    # ------------------------------------------------------------------ sampling
    @property
    def inpaint_overlaps(self) -> bool:
        """Whether long-form windows in-paint their overlaps (a checkpoint from before the option: yes)."""
        return bool(self.hparams.get("inpaint_overlaps", True))

    @torch.no_grad()
    def estimate_head(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Head positions (B, T, 3) and rotations (B, T, 3, 3) estimated from frames (B, T, 3, H, W)."""
        if self.head_estimator is None:
            raise ValueError("this EgoDanceModule has no head-trajectory estimator (a music-only model?)")
        was_training = self.head_estimator.training
        self.head_estimator.eval()
        try:
            return self.head_estimator(frames)
        finally:
            self.head_estimator.train(was_training)

    def head_targets(self, batch: dict, source: str | None = None) -> torch.Tensor | None:
        """Head guidance targets (B, T, 3) of ``source`` (default ``head_guidance.source``), or None for
        ``none``."""
        source = source or self.head_guidance.source
        if source == "none":
            return None
        if source == "oracle":
            if batch.get("head") is None:
                raise ValueError("head_source='oracle' needs the ground-truth head path (batch['head'])")
            return batch["head"]
        if source == "estimate":
            if batch.get("frames") is None:
                raise ValueError("head_source='estimate' needs the egocentric frames (batch['frames'])")
            return self.estimate_head(batch["frames"])[0]
        raise ValueError(f"unknown head source {source!r} ({', '.join(HEAD_SOURCES)})")

    def sample(
        self,
        batch: dict,
        batch_idx: int = 0,
        use_ema: bool = True,
        head_source: str | None = None,
        head: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Motion tokens (B, T, 24, 10) for a batch's music and frames, head guidance from ``head_source``
        (default: ``head_guidance.source``) or the given ``head`` targets (B, T, 3). Sequences longer than
        the training ``window`` are danced long-form, one by one (:meth:`sample_long`)."""
        model = self.ema.module if use_ema else self.model
        if batch["music"].shape[1] > self.hparams.window:
            generator = torch.Generator().manual_seed(self.evaluation.seed + batch_idx)
            source = head_source or self.head_guidance.source
            return torch.stack(
                [self.sample_long(model, batch, i, source, generator) for i in range(len(batch["music"]))]
            )
        if head is None:
            head = self.head_targets(batch, head_source)
        return sample_dance(
            model,
            self.diffusion,
            batch["music"],
            batch.get("frames"),
            head,
            **dataclasses.asdict(self.sampling),
            head_guidance_weight=self.head_guidance.weight,
            head_guidance_steps=self.head_guidance.steps,
            generator=torch.Generator().manual_seed(self.evaluation.seed + batch_idx),
            heading=self.condition_heading(model, batch),
        )

    def sample_long(
        self, model: EMM, batch: dict, index: int, source: str, generator: torch.Generator
    ) -> torch.Tensor:
        """Tokens (T, 24, 10) of sequence ``index`` of the batch, danced in overlapping windows of the
        training length (overlap: half a window, EDGE's 75 of 150) in the frames the model was trained in,
        each window's head targets in its own frame (:func:`.long_form.head_targets`)."""
        hp = self.hparams
        long_form = LongForm(hp.window, hp.window // 2, bool(hp.canonicalize_init_head))
        music = batch["music"][index]
        frames = None if batch.get("frames") is None else batch["frames"][index]
        truth, head = (None if batch.get(k) is None else batch[k][index] for k in ("motion", "head"))
        if source == "oracle" and head is None:
            raise ValueError("head_source='oracle' needs the ground-truth head path (batch['head'])")
        if source == "estimate" and frames is None:
            raise ValueError("head_source='estimate' needs the egocentric frames (batch['frames'])")
        head, head_windows = head_targets(
            source, long_form, len(music), self.head_estimator, frames, truth, head
        )
        return sample_long_dance(
            model,
            self.diffusion,
            music,
            frames,
            head,
            long_form.window,
            long_form.overlap,
            canonical=long_form.canonical,
            head_windows=head_windows,
            **dataclasses.asdict(self.sampling),
            head_guidance_weight=self.head_guidance.weight,
            head_guidance_steps=self.head_guidance.steps,
            generator=generator,
            headings=self.condition_heading(model, batch, index),
            inpaint=self.inpaint_overlaps,
        )

    def _test_sources(self, batch: dict) -> list[str]:
        sources = [self.head_guidance.source]
        if self.head_guidance.test_oracle and "oracle" not in sources and batch.get("head") is not None:
            sources.append("oracle")
        return sources

    def on_test_start(self) -> None:
        record_audio_stack(self.loggers)  # hyperparameter audio_stack: the versions that decide the beats

    def test_step(self, batch: dict, batch_idx: int) -> None:
        true = motion_joints(batch["motion"])
        if "music_path" not in batch:
            raise KeyError("EMM test: the batch needs music_path and music_start_s (protocol music beats)")
        frames = batch.get("frames")
        beats = video_beats(frames) if frames is not None else None
        estimate = None
        long = true.shape[1] > self.hparams.window  # danced long-form: each window estimates its own head
        if self.head_estimator is not None and frames is not None and not long:
            estimate = self.estimate_head(frames)
            if batch.get("head_rotation") is not None:
                pos_err, rot_err = head_trajectory_errors(*estimate, batch["head"], batch["head_rotation"])
                self.test_head_position.update(pos_err)
                self.test_head_rotation.update(rot_err)
                b = len(pos_err)
                self.log("test/head_estimator/position_mm", self.test_head_position, batch_size=b)
                self.log("test/head_estimator/rotation_deg", self.test_head_rotation, batch_size=b)
        protocol = next(iter(self.test_evaluations.values())).protocol
        cache = getattr(self.contract, "music_cache_dir", None)  # the data's feature cache
        fps = self.hparams.fps
        duration = true.shape[1] / fps
        music_beats = [
            protocol.music_beats(path, float(start), duration, cache)
            for path, start in zip(batch["music_path"], batch["music_start_s"])
        ]
        for source in self._test_sources(batch):
            head = estimate[0] if source == "estimate" and estimate is not None else None
            pred = motion_joints(self.sample(batch, batch_idx, head_source=source, head=head))
            name = HEAD_SOURCES[source]
            self.test_metrics[name].update(pred, true, batch["music"], beats)
            for i, window_beats in enumerate(music_beats):
                self.test_evaluations[name].add(true[i].cpu(), fps, window_beats, real=True)
                self.test_evaluations[name].add(pred[i].cpu(), fps, window_beats)

    def on_test_epoch_end(self) -> None:
        names = {"BeatAlign": "beat_align", "PFC": "pfc", "FID_k": "FID_k", "FID_g": "FID_g",
                 "Div_k": "Div_k", "Div_g": "Div_g"}  # fmt: skip
        for name, group in self.test_metrics.items():
            evaluation = self.test_evaluations[name]
            if group.mpjpe.update_called:
                values = {k: float(v) for k, v in group.compute().items()}
                result = evaluation.compute()
                values.update({short: float(result[key]) for key, short in names.items() if key in result})
                self.log_dict({f"test/{name}/{k}": v for k, v in values.items()})
            group.reset()
            evaluation.reset(keep_real=False)

    def configure_callbacks(self) -> list:
        """``sm predict`` writes every dance as files in the log dir (:class:`DancePredictionWriter`)."""
        return [DancePredictionWriter()]

    def predict_step(self, batch: dict, batch_idx: int) -> dict:
        """``sample_id``, ``tokens`` (B, T, 24, 10), FK ``joints`` (B, T, 24, 3) of sampled dances, and the
        ``head_source`` their guidance used."""
        tokens = self.sample(batch, batch_idx)
        return {
            "sample_id": batch.get("sample_id"),
            "tokens": tokens,
            "joints": motion_joints(tokens),
            "head_source": self.head_guidance.source,
        }

    def configure_optimizers(self):
        params = [p for p in self.model.parameters() if p.requires_grad]
        if self.head_estimator is not None:
            params += list(self.head_estimator.parameters())
        options = self.optimizer_options
        return torch.optim.AdamW(params, lr=options.lr, weight_decay=options.weight_decay)
