"""LightningModule for QEAN: L2 training on 20-frame futures, AIST++ evaluation, dance generation.

Training ([QEAN] Sec. 4.2): Adam, lr 1e-4 decayed by 10 at 90k and 150k optimizer steps
(``MultiStepLR`` stepped per step), L2 (mean squared error) between the predicted and true next 20 frames.

Test: each test sequence's first 120 frames seed an autoregressive generation of 1200 frames
(:func:`.generate.generate_fast`) over its music, scored on SMPL-24 joints from the toolkit's offset-table FK
under a named evaluation protocol (``protocol``, :mod:`~skeleton_mamba.tasks.motion.metrics.protocols`),
default ``"fact"``, the [QEAN] paper's (FACT's metric code): FID_k / FID_g of the generated frames after the
seed against the full-length real set (the data module's ``reference_joints``), Dist_k / Dist_g of the
generated set (both normalised by the real statistics), and BeatAlign in FACT's form from frame 120 against
every beat of the track. ``"bailando"`` and ``"edge"`` score the same generations the other papers' ways.
They are logged as ``test/FID_k`` ... and printed beside [QEAN] Table 1, headed by the protocol actually
run (name, sequences x frames, size of the real set). The paper's 40 sequences are the crossmodal val + test
lists (the data module's default, see :mod:`.data`); another protocol, count or length, or data marked
``synthetic``, is labelled NOT COMPARABLE in the table.

Predict: generate ``generate_frames`` frames for the data module's seed motion and music, save the seed and
the dance as our ``.npz`` motion format (``smpl_poses``, ``smpl_trans``, ``joints``, 60 fps) and render an
mp4 with the music.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from lightning.pytorch.utilities import rank_zero_info

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.motion.formats.export import write_motion
from skeleton_mamba.tasks.motion.formats.fact_features import FPS, features_to_joints, features_to_smpl
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.motion.metrics.evaluation import DanceEvaluation
from skeleton_mamba.tasks.motion.metrics.protocols import PROTOCOLS, FACTProtocol, get_protocol
from skeleton_mamba.tasks.motion.music.features import beat_frames, describe_audio_stack, record_audio_stack
from skeleton_mamba.tasks.qean.generate import generate_fast
from skeleton_mamba.tasks.qean.model import QEAN, QEANConfig
from skeleton_mamba.tasks.training.backbone_config import config_from, plain_backbone_config
from skeleton_mamba.tasks.training.base_module import BackboneModule, attached_trainer
from skeleton_mamba.tasks.training.prediction_rig import PredictionRig

__all__ = ["QEANModule", "QEAN_TABLE1", "features_to_motion"]

# [QEAN] Table 1 (QEAN row and the AIST++ ground-truth row), printed beside our test figures.
QEAN_TABLE1 = {
    "FID_k": (30.1, None),
    "FID_g": (11.5, None),
    "Dist_k": (7.82, 9.057),
    "Dist_g": (9.37, 7.556),
    "BeatAlign": (0.239, 0.292),
}
# Our test figures, named as [QEAN] Table 1 names them -> the key DanceEvaluation.compute() gives them under
# (FID and Dist only from 2 generated sequences on; PFC only under the EDGE protocol).
TEST_FIGURES = {
    "FID_k": "FID_k",
    "FID_g": "FID_g",
    "Dist_k": "Div_k",
    "Dist_g": "Div_g",
    "BeatAlign": "BeatAlign",
    "PFC": "PFC",
}
PAPER_SEQUENCES = 40  # generated sequences of [QEAN]'s protocol (crossmodal val + test)
PAPER_FRAMES = 1200  # frames generated after each seed motion (20 s at 60 fps)


def features_to_motion(features: torch.Tensor) -> MotionData:
    """A (T, 219) motion vector sequence -> our motion format (SMPL poses, root, joints; 60 fps)."""
    poses, root = features_to_smpl(features.double())
    return MotionData(
        fps=FPS,
        skeleton="smpl24",
        poses=poses.cpu().numpy().astype(np.float32),
        trans=root.cpu().numpy().astype(np.float32),
        scaling=1.0,
        joints=features_to_joints(features.double()).cpu().numpy().astype(np.float32),
    )


class QEANModule(BackboneModule):
    """QEAN music-to-dance generation.

    Args:
        backbone: a SkeletonMamba config (``backbones/skeleton_mamba.yaml``) used as the motion encoder;
            ``None`` uses [QEAN]'s motion transformer.
        network: QEAN's sizes and window lengths (:class:`~.model.QEANConfig`; None: its defaults, [QEAN]
            Sec. 4.2). Under ``sm`` its ``seed_frames``, ``music_frames`` and ``predict_frames`` are linked
            from the data module (set them there).
        lr: Adam learning rate (1e-4).
        lr_milestones: optimizer steps where the learning rate is multiplied by ``lr_gamma`` (90k, 150k).
        lr_gamma: decay factor (0.1: 1e-4 -> 1e-5 -> 1e-6).
        generate_frames: frames generated at test/predict time (1200; under ``sm`` linked from the data).
        audio_chunk: music windows encoded per batched call in fast generation.
        output_dir: folder for ``sm predict`` outputs.
        render: also render an mp4 at predict time.
        protocol: dance-evaluation protocol of the test loop, ``"fact"`` (default, [QEAN]'s), ``"bailando"``
            or ``"edge"`` (see :mod:`~skeleton_mamba.tasks.motion.metrics.protocols`).
        rollout_probability: share of the training windows whose seed ends in the model's own frames (ours;
            0, the default, is [QEAN]'s teacher forcing). Generation feeds the network its own frames, which
            teacher forcing never shows it: each step's small error pulls the dance towards the mean, and it
            freezes (exposure bias). With windows that carry R earlier frames (the data's
            ``rollout_frames``), the network first predicts R frames from the R-earlier seed (no gradient;
            in steps of ``predict_frames``, each from the seed the previous steps left, when R is larger),
            they replace the seed's last R frames, and the loss asks for the true future from there, so the
            network learns to return to the dance from its own frames (R = ``seed_frames``: from a seed
            entirely its own, as generation gives it after its first window).
    """

    def __init__(
        self,
        backbone: SkeletonMambaConfig | None = None,
        network: QEANConfig | None = None,
        lr: float = 1e-4,
        lr_milestones: list[int] | None = None,
        lr_gamma: float = 0.1,
        generate_frames: int = 1200,
        audio_chunk: int = 32,
        output_dir: str = "qean_predictions",
        render: bool = True,
        protocol: str = "fact",
        rollout_probability: float = 0.0,
    ) -> None:
        super().__init__()
        network = config_from(QEANConfig, network)
        if not 0.0 <= rollout_probability <= 1.0:
            raise ValueError(f"rollout_probability must be in [0, 1], got {rollout_probability}")
        if protocol not in PROTOCOLS:
            raise ValueError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
        ignore = ("network",)
        backbone_cfg = self.save_backbone_hyperparameters(backbone, ignore=ignore, optional=True)
        self.hparams["network"] = plain_backbone_config(network)
        self.lr_milestones = [90_000, 150_000] if lr_milestones is None else list(lr_milestones)
        self.model = QEAN(network, backbone_cfg)
        scorer = FACTProtocol(network.seed_frames) if protocol == "fact" else get_protocol(protocol)
        self.test_evaluation = DanceEvaluation(scorer)
        self._reference_loaded = False
        self._reference_count = 0
        self._generated_count = 0

    def forward(self, motion: torch.Tensor, music: torch.Tensor) -> torch.Tensor:
        """Seed (B, 120, 219) and music (B, 240, 35) -> the next frames (B, 20, 219)."""
        return self.model(motion, music)

    def setup(self, stage: str) -> None:
        """The window lengths must be the data's (:class:`~.data.QEANContract`; ``sm`` links them, a module
        built by hand may differ)."""
        super().setup(stage)
        contract = self.contract
        lengths = ("seed_frames", "music_frames", "predict_frames")
        ours = {key: getattr(self.model.config, key) for key in lengths}
        ours["generate_frames"] = self.hparams.generate_frames
        for key, value in ours.items():
            data = getattr(contract, key, None)  # None: built by hand, or data without these lengths
            if data is not None and data != value:
                raise ValueError(
                    f"the model's {key} = {value} but data.{key} = {data}: set both to the same "
                    "value (sm links them from the data module)"
                )

    def rollout_seed(self, motion: torch.Tensor, music: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """A training window's seed and music: motion (B, R + S, 219) and music (B, R + M, 35) carrying R
        earlier frames -> seed (B, S, 219), music (B, M, 35). The seed is the last S true frames, or, for a
        ``rollout_probability`` share of the windows, its last R frames are the network's prediction (no
        gradient) from the seed R frames earlier (frames ``[0, S)``, music ``[0, M)``), chained in steps of
        P = ``predict_frames`` as generation chains them: step k predicts frames ``[S + kP, S + (k+1)P)``
        from frames ``[kP, S + kP)`` as the earlier steps left them, and music ``[kP, M + kP)``."""
        c = self.model.config
        extra = motion.shape[1] - c.seed_frames
        seed, future_music = motion[:, extra:], music[:, extra:]
        if extra == 0 or self.hparams.rollout_probability == 0 or not self.training:
            return seed, future_music
        rolled = torch.rand(motion.shape[0], device=motion.device) < self.hparams.rollout_probability
        if not rolled.any():
            return seed, future_music
        chained, chained_music = motion[rolled].clone(), music[rolled]
        with torch.no_grad():
            for start in range(0, extra, c.predict_frames):
                window = chained[:, start : start + c.seed_frames]
                own = self.model(window, chained_music[:, start : start + c.music_frames])
                keep = min(c.predict_frames, extra - start)
                chained[:, start + c.seed_frames : start + c.seed_frames + keep] = own[:, :keep]
        seed = seed.clone()
        seed[rolled] = chained[:, extra:]
        return seed, future_music

    def training_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> torch.Tensor:
        pred = self.model(*self.rollout_seed(batch["motion"], batch["music"]))
        loss = F.mse_loss(pred, batch["target"])
        self.log("train/loss", loss, prog_bar=True, batch_size=pred.shape[0])
        return loss

    def configure_optimizers(self):
        optimizer = torch.optim.Adam(self.parameters(), lr=self.hparams.lr)
        scheduler = torch.optim.lr_scheduler.MultiStepLR(optimizer, self.lr_milestones, self.hparams.lr_gamma)
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "step"}}

    # ----- generation -----
    def generate(
        self, seed: torch.Tensor, music: torch.Tensor, progress: bool = False, frames: int | None = None
    ) -> torch.Tensor:
        """Seed (B, 120, 219) + music (B, T, 35) -> ``[seed | generated]`` (B, 120 + G, 219), G = ``frames``
        or ``generate_frames``."""
        count = self.hparams.generate_frames if frames is None else frames
        generated = generate_fast(self.model, seed, music, count, self.hparams.audio_chunk, progress)
        return torch.cat([seed[:, -self.model.config.seed_frames :], generated], dim=1)

    # ----- test -----
    def on_test_epoch_start(self) -> None:
        self._generated_count = 0
        record_audio_stack(self.loggers)  # the versions that decide the music beats
        if self._reference_loaded:
            return
        datamodule = self.trainer.datamodule
        if not hasattr(datamodule, "reference_joints"):
            raise TypeError(
                "QEAN test metrics need a data module with reference_joints() (AISTPPDanceDataModule)"
            )
        self.test_evaluation.reset(keep_real=False)
        for joints in datamodule.reference_joints():
            self.test_evaluation.add(joints.double(), FPS, real=True)
        self._reference_loaded = True
        self._reference_count = self.test_evaluation.counts["real"]
        rank_zero_info(f"QEAN test: real set of {self._reference_count} AIST++ clips")

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self.score_generated(batch, self.generate(batch["seed"], batch["music"]))

    def score_generated(self, batch: dict, full: torch.Tensor) -> torch.Tensor:
        """Add the generations ``full`` (B, 120 + G, 219) of a test batch to the test metrics; returns their
        joints (B, 120 + G, 24, 3)."""
        joints = features_to_joints(full.double())  # (B, 120 + G, 24, 3)
        protocol = self.test_evaluation.protocol
        cache = getattr(self.contract, "music_cache_dir", None)  # the data's feature cache
        for i in range(full.shape[0]):
            if protocol.name == "fact":  # the data module's features are FACT's: beats of the whole window
                beats = beat_frames(batch["music"][i].cpu().numpy())
            else:
                beats = protocol.music_beats(batch["music_path"][i], cache_dir=cache)
            self.test_evaluation.add(joints[i].cpu(), FPS, beats)
        self._generated_count += full.shape[0]
        return joints

    def test_scores(self) -> dict[str, float]:
        """The test figures of everything scored since the last call (FID_k ... BeatAlign, PFC when the
        protocol has it; FID and Dist only from 2 generated sequences on); the generated set is cleared, the
        real set kept."""
        result = self.test_evaluation.compute()
        values = {ours: float(result[key]) for ours, key in TEST_FIGURES.items() if key in result}
        self.test_evaluation.reset(keep_real=True)
        return values

    def on_test_epoch_end(self) -> None:
        values = self.test_scores()
        for name, value in values.items():
            self.log(f"test/{name}", value)
        rank_zero_info(self.results_table(values))

    def constant_real_features(self) -> dict[str, int]:
        """Kinetic and geometric feature dimensions constant over the test's real set (see
        :meth:`~skeleton_mamba.tasks.motion.metrics.fid.FrechetMotionDistance.constant_real_features`)."""
        return {kind: fid.constant_real_features() for kind, fid in self.test_evaluation.fid.items()}

    def results_table(self, values: dict[str, float]) -> str:
        """Our test figures beside [QEAN] Table 1, headed by the protocol run and its comparability."""
        sequences, frames = self._generated_count, self.hparams.generate_frames
        synthetic = bool(getattr(getattr(attached_trainer(self), "datamodule", None), "synthetic", False))
        reasons = ["synthetic data in the AIST++ layout, not AIST++"] if synthetic else []
        protocol = self.hparams.get("protocol", "fact")
        if protocol != "fact":
            reasons.append(f"protocol {protocol} ([QEAN] Table 1 follows FACT's)")
        if sequences != PAPER_SEQUENCES:
            reasons.append(f"{sequences} sequences instead of {PAPER_SEQUENCES}")
        if frames != PAPER_FRAMES:
            reasons.append(f"{frames} frames instead of {PAPER_FRAMES}")
        lines = [
            "QEAN test vs [QEAN] Table 1",
            f"protocol {protocol}: {sequences} generated sequences x {frames} frames "
            f"(paper: {PAPER_SEQUENCES} x {PAPER_FRAMES}); real set: {self._reference_count} sequences",
            f"NOT COMPARABLE with [QEAN] Table 1: {'; '.join(reasons)}" if reasons else "paper protocol",
            f"audio stack: {describe_audio_stack()}",
            f"{'metric':<10} {'ours':>10} {'QEAN (paper)':>12} {'AIST++ GT':>10}",
        ]
        if "FID_k" not in values:
            lines.append(f"FID and Dist need at least 2 generated sequences ({sequences} scored)")
        for name, value in values.items():
            paper, gt = QEAN_TABLE1.get(name, ("-", None))
            lines.append(f"{name:<10} {value:>10.3f} {paper:>12} {'-' if gt is None else gt:>10}")
        for kind, constant in self.constant_real_features().items():
            if constant:
                short = kind[0]
                lines.append(
                    f"FID_{short} / Dist_{short}: {constant} {kind} features never vary over the real set; "
                    "the reference normalisation divides them by std + 1e-10, so a dance that sets them "
                    "scores ~1e10 or more (a property of the real set, not a measure of the dance)"
                )
        return "\n".join(lines)

    # ----- predict -----
    def predict_step(self, batch: dict, batch_idx: int) -> list[Path]:
        """Generate and write ``<output_dir>/<name>.npz / .bvh / .glb`` (and ``.mp4`` with its ``.wav``, the
        music's slice of the dance's length, when ``render``; ``<name>_rig.glb`` / ``.vrm`` / ``.bvh`` with
        ``sm predict --rig``: :mod:`~skeleton_mamba.tasks.training.prediction_rig`); returns the written
        paths."""
        frames = int(batch["frames"].max())  # the song's length after the seed (batches of one song)
        full = self.generate(batch["seed"], batch["music"], frames=frames)  # Lightning's bar counts songs
        written = []
        for i, name in enumerate(batch["name"]):
            motion = features_to_motion(full[i])
            music, render = batch["music_path"][i], self.hparams.render
            files = write_motion(motion, self.hparams.output_dir, name, music=music, render=render)
            if (rig := PredictionRig.of(attached_trainer(self))) is not None:  # sm predict --rig
                files.rig = rig.write(files.npz, name)
            paths = [p for p in vars(files).values() if p is not None]
            written.extend(paths)
            rank_zero_info(f"QEAN: wrote {', '.join(str(p) for p in paths)}")
        return written
