"""LightningModule for text-to-motion diffusion ([EgoMusic] supp. Sec. 8.2, [MDM]'s recipe).

Training (MDM, ``GuyTevet/motion-diffusion-model``): x0 prediction with the shared
:class:`~skeleton_mamba.tasks.training.diffusion.GaussianDiffusion` (cosine schedule, 1,000 steps, uniform t),
masked MSE ``|x0 - x0_hat|^2`` over valid frames, the caption dropped with probability 0.1 for
classifier-free guidance, AdamW (lr 1e-4, weight decay 0). Sampling (the shared
:func:`~skeleton_mamba.tasks.training.diffusion.sample`): classifier-free guidance ``unc + s (cond - unc)``
with s = ``guidance_weight`` = 2.5, ``sampler`` ancestral DDPM over all steps (MDM) or DDIM with
``sampling_steps`` steps and noise ``eta``.

The text encoder (:class:`~.text_encoder.TextEncoder`, frozen) is kept outside the module's state:
checkpoints hold only the denoiser and the feature statistics (``feature_mean``, ``feature_std``,
copied from the data module's ``statistics()`` at setup), so generation de-normalises on its own.

``sm test`` reports the test loss and then runs the T2M evaluation protocol (:mod:`.evaluation`:
``evaluation.repetitions`` replications of R-Precision, FID, MM-Dist, Diversity and, when
``evaluation.mm_samples`` > 0, MultiModality, for the real test motions and for the model), prints the
table with 95 % intervals and writes ``t2m_evaluation.json`` / ``.csv`` in the log folder. The table is
labelled comparable with published numbers only when the official evaluator checkpoint, its statistics
and GloVe were loaded.
The ``evaluation`` settings (:class:`~.evaluation.T2MEvalConfig`) and ``eval_sampling_steps`` are not saved in
checkpoints, so ``sm test --ckpt_path CKPT --model.evaluation.repetitions 2`` takes them from the recipe and
command line.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FEATURE_DIM, read_feature_vector
from skeleton_mamba.tasks.text2motion.evaluation import T2MEvalConfig, T2MEvaluation
from skeleton_mamba.tasks.text2motion.evaluation_report import (
    COMPARABLE,
    NOT_COMPARABLE,
    format_table,
    summarize,
    write_report,
)
from skeleton_mamba.tasks.text2motion.evaluator import load_evaluator
from skeleton_mamba.tasks.text2motion.glove import HashedWordVectorizer, WordVectorizer
from skeleton_mamba.tasks.text2motion.model import LengthMaskedDenoiser, TextCondition, TextToMotionDenoiser
from skeleton_mamba.tasks.text2motion.text_encoder import TextEncoder
from skeleton_mamba.tasks.training.backbone_config import config_from
from skeleton_mamba.tasks.training.base_module import BackboneModule
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, SamplingOptions, sample
from skeleton_mamba.tasks.training.progress_bar import live_bars_shown

__all__ = ["TextToMotionModule"]

DEFAULT_SAMPLING_STEPS = 50  # DDIM steps when none is given


class _Unregistered:
    """Holds a module as a plain attribute of another: ``nn.Module`` registers only attributes that are
    modules, parameters or buffers, so the held one stays out of the owner's ``state_dict``,
    ``parameters()``, ``to()`` and ``train()``."""

    def __init__(self, module: torch.nn.Module) -> None:
        self.module = module


class TextToMotionModule(BackboneModule):
    """Skeleton Mamba text-to-motion diffusion.

    Args:
        backbone: backbone configuration (recipes include ``backbones/skeleton_mamba.yaml``).
        text_encoder_path: local CLIP / transformers folder; ``None`` = the packaged MiniLM.
        max_tokens: caption tokens kept by the text encoder.
        time_channels: timestep channels appended to every joint token.
        diffusion_steps: diffusion steps T (1000).
        cond_drop_prob: probability of dropping the caption in training (0.1).
        guidance_weight: classifier-free guidance scale s at sampling (2.5).
        sampler: ``ddpm`` (all T steps, MDM) or ``ddim`` at sampling.
        sampling_steps: DDIM steps.
        eta: DDIM noise (0: deterministic).
        lr: AdamW learning rate (1e-4).
        weight_decay: AdamW weight decay (0).
        evaluation: the T2M evaluation of ``sm test`` (:class:`~.evaluation.T2MEvalConfig`: the protocol's
            sizes, MDM's by default, ``repetitions: 0`` reports the test loss only; the evaluator's files).
        eval_sampler: the evaluation's sampler (``None``: the module's ``sampler``).
        eval_sampling_steps: the evaluation's DDIM steps (``None``: the module's; a number alone selects
            DDIM).
        temporal_prior: precondition the denoiser with a Gaussian process over time with the training data's
            spectrum (:class:`~.model.TextToMotionDenoiser`).
        pooled_text: also add the caption's pooled embedding to the timestep embedding ([MDM]'s sum), so it
            reaches every joint token's input besides the cross-attention ([EgoMusic]'s only path).
    """

    def __init__(
        self,
        backbone: SkeletonMambaConfig | None = None,
        text_encoder_path: str | None = None,
        max_tokens: int = 77,
        time_channels: int = 16,
        diffusion_steps: int = 1000,
        cond_drop_prob: float = 0.1,
        guidance_weight: float = 2.5,
        sampler: str = "ddpm",
        sampling_steps: int = DEFAULT_SAMPLING_STEPS,
        eta: float = 0.0,
        lr: float = 1e-4,
        weight_decay: float = 0.0,
        evaluation: T2MEvalConfig | None = None,
        eval_sampler: str | None = None,
        eval_sampling_steps: int | None = None,
        temporal_prior: bool = False,
        pooled_text: bool = False,
    ) -> None:
        super().__init__()
        options = SamplingOptions(sampler, sampling_steps, eta, guidance_weight)
        options.check_steps(diffusion_steps)  # the step counts against T, when the module is made
        try:
            options.override(eval_sampler, eval_sampling_steps).check_steps(diffusion_steps)
        except ValueError as err:
            raise ValueError(
                f"the evaluation's sampling (eval_sampler, eval_sampling_steps): {err}"
            ) from None
        # Evaluation settings are test-time options kept out of the checkpoint's hyperparameters: LightningCLI
        # lets a checkpoint's hyperparameters override the command line, which would freeze them at training
        # time.
        self.eval_options = config_from(T2MEvalConfig, evaluation)
        self.eval_sampler, self.eval_sampling_steps = eval_sampler, eval_sampling_steps
        config = self.save_backbone_hyperparameters(
            backbone, ignore=("evaluation", "eval_sampler", "eval_sampling_steps", "num_steps")
        )
        # the new spellings (LightningCLI saves the arguments as given, old spellings included)
        self.hparams.update(diffusion_steps=diffusion_steps, sampler=sampler, sampling_steps=sampling_steps)
        # not a registered submodule: frozen pretrained weights stay out of checkpoints
        self._text_encoder = _Unregistered(TextEncoder(text_encoder_path, max_tokens=max_tokens))
        self.denoiser = TextToMotionDenoiser(
            config,
            self.text_encoder.dim,
            time_channels,
            diffusion_steps=diffusion_steps,
            temporal_prior=temporal_prior,
            pooled_text=pooled_text,
        )
        self.diffusion = GaussianDiffusion(diffusion_steps)
        self.register_buffer("feature_mean", torch.zeros(FEATURE_DIM))
        self.register_buffer("feature_std", torch.ones(FEATURE_DIM))

    def set_data_statistics(self, statistics) -> None:
        """The data's normalisation (``feature_mean``, ``feature_std``) into the module's buffers and the
        denoiser's preconditioning from the normalised training ``features``
        (:class:`.data.TextMotionStatistics`)."""
        self.feature_mean.copy_(statistics.feature_mean)
        self.feature_std.copy_(statistics.feature_std)
        if statistics.features is not None:
            self.denoiser.set_data_statistics(statistics.features, statistics.feature_lengths)

    @property
    def text_encoder(self) -> TextEncoder:
        """The frozen text encoder, kept outside the module's state (see the module docstring)."""
        return self._text_encoder.module

    def encode_text(self, captions: list[str]) -> TextCondition:
        """Frozen text encoding on the module's device: tokens (B, S, D) and mask (B, S)."""
        self.text_encoder.to(self.device)
        tokens, mask = self.text_encoder(captions)
        return TextCondition(tokens, mask)

    def loss(self, batch: dict, drop_prob: float) -> torch.Tensor:
        """Masked x0 MSE of one batch with caption dropout ``drop_prob``."""
        x0, mask = batch["motion"], batch["mask"]
        cond = self.encode_text(batch["caption"])
        if drop_prob > 0:
            keep = torch.rand(x0.shape[0], device=self.device) >= drop_prob
            cond = TextCondition(cond.tokens, cond.mask & keep[:, None])
        x_t, t, target = self.diffusion.training_pair(x0)
        x0_hat = self.denoiser(x_t, t, cond, mask)
        weights = mask[..., None].to(x0.dtype)
        return ((x0_hat - target) ** 2 * weights).sum() / (weights.sum() * x0.shape[-1])

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        loss = self.loss(batch, self.hparams.cond_drop_prob)
        self.log("train/loss", loss, prog_bar=True, batch_size=len(batch["caption"]))
        return loss

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        loss = self.loss(batch, 0.0)
        self.log("val/loss", loss, prog_bar=True, batch_size=len(batch["caption"]), sync_dist=True)

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self.log("test/loss", self.loss(batch, 0.0), batch_size=len(batch["caption"]), sync_dist=True)

    def on_test_epoch_end(self) -> None:
        """Run the T2M protocol, print its table and write it as JSON / CSV in the log folder."""
        if self.eval_options.repetitions < 1:
            return
        evaluation, label = self._t2m_evaluation()
        sampling = self.sampling.override(self.eval_sampler, self.eval_sampling_steps)

        def generate(captions: list[str], lengths: list[int], noise: torch.Generator) -> torch.Tensor:
            return self.generate(captions, lengths, generator=noise, **dataclasses.asdict(sampling))[0]

        progress = self.trainer.progress_bar_callback is not None and live_bars_shown()  # none in a log file
        summary = summarize(evaluation.run(generate, progress=progress))
        folder = Path(self.trainer.log_dir or self.trainer.default_root_dir)
        protocol = {**evaluation.describe(), **sampling.describe()}
        protocol["evaluator_checkpoint"] = self.eval_options.evaluator_checkpoint
        json_path, csv_path = write_report(folder, summary, label, protocol)
        self.print(format_table(summary, label))
        self.print(f"wrote {json_path} and {csv_path}")
        self.log_dict({f"test/{k}": v["mean"] for k, v in summary["model"].items()})

    def _t2m_evaluation(self) -> tuple[T2MEvaluation, str]:
        """The evaluation over the data module's test clips, and the comparability label."""
        hp = self.eval_options
        datamodule = self.trainer.datamodule
        if not hasattr(datamodule, "evaluation_clips"):
            raise RuntimeError("the T2M evaluation needs a text2motion data module (evaluation_clips())")
        checkpoint = hp.evaluator_checkpoint
        official = checkpoint is not None and Path(checkpoint).suffix != ".ckpt"
        if checkpoint is not None and hp.glove_dir is None:
            raise ValueError(f"evaluator_checkpoint {checkpoint} needs glove_dir (its our_vab_* GloVe files)")
        if (hp.evaluator_mean is None) != (hp.evaluator_std is None):
            raise ValueError("set both evaluator_mean and evaluator_std, or neither")
        if official and hp.evaluator_mean is None:
            raise ValueError(
                f"the official evaluator {checkpoint} needs evaluator_mean / evaluator_std "
                "(MDM dataset/t2m_mean.npy and t2m_std.npy)"
            )
        evaluator = load_evaluator(checkpoint, FEATURE_DIM, hp.seed).to(self.device)
        words = WordVectorizer(hp.glove_dir) if hp.glove_dir else HashedWordVectorizer(seed=hp.seed)
        if hp.evaluator_mean is not None:
            mean = read_feature_vector(hp.evaluator_mean, "evaluator Mean")
            std = read_feature_vector(hp.evaluator_std, "evaluator Std")
        else:
            mean, std = self.feature_mean.cpu().numpy(), self.feature_std.cpu().numpy()
        clips = datamodule.evaluation_clips("test")
        label = COMPARABLE if evaluator.comparable else NOT_COMPARABLE
        return T2MEvaluation(evaluator, clips, words, mean, std, hp.protocol), label

    @property
    def sampling(self) -> SamplingOptions:
        """The module's sampling: ``sampler``, ``sampling_steps``, ``eta``, ``guidance_weight``."""
        return SamplingOptions.from_hparams(self.hparams)

    @torch.no_grad()
    def generate(
        self,
        captions: list[str],
        lengths: list[int],
        generator: torch.Generator | None = None,
        guidance_weight: float | None = None,
        sampling_steps: int | None = None,
        progress: bool = False,
        sampler: str | None = None,
        eta: float | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Sample motions for captions.

        Args:
            captions: B captions.
            lengths: B lengths in frames (20 fps).
            generator: CPU generator for reproducible noise.
            guidance_weight: override of the module's :attr:`sampling` (``None`` keeps its setting; as
                :meth:`~skeleton_mamba.tasks.training.diffusion.SamplingOptions.override`).
            sampling_steps: override likewise (a step count alone selects DDIM).
            sampler: override likewise.
            eta: override likewise.
            progress: show a progress bar.

        Returns:
            De-normalised features (B, T_max, 263) (zeros past each length) and the mask (B, T_max).
        """
        options = self.sampling.override(sampler, sampling_steps, eta, guidance_weight)
        options.check_steps(self.diffusion.num_steps)  # before the captions are encoded
        lengths_t = torch.tensor(lengths, device=self.device)
        mask = torch.arange(int(lengths_t.max()), device=self.device)[None] < lengths_t[:, None]
        cond = self.encode_text(captions)
        denoiser = LengthMaskedDenoiser(self.denoiser, mask)  # guidance: one call on a doubled batch
        shape = (len(captions), mask.shape[1], FEATURE_DIM)
        x = sample(
            self.diffusion,
            denoiser,
            shape,
            cond,
            **dataclasses.asdict(options),
            generator=generator,
            device=self.device,
            progress=progress,
        )
        features = (x * self.feature_std + self.feature_mean) * mask[..., None]
        return features, mask

    def predict_step(self, batch: dict, batch_idx: int) -> dict:
        features, mask = self.generate(batch["caption"], batch["length"].tolist())
        return {"features": features, "mask": mask, "caption": batch["caption"]}

    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.AdamW(
            self.denoiser.parameters(), lr=self.hparams.lr, weight_decay=self.hparams.weight_decay
        )
