"""The QEAN demo's last act: after training, dance from held-out seed motions and music, and score it.

:class:`QEANDemo` is a Lightning callback (``qean_demo.yaml`` configures it). When ``fit`` ends it takes the
data module's test items (the held-out ``val`` split of the SYNTHETIC demo set: seed motions and music never
seen in training) and generates each dance as ``sm test`` does: the first ``seed_frames`` frames of the
sequence seed [QEAN]'s autoregressive generation (:meth:`QEANModule.generate`, i.e.
:func:`~skeleton_mamba.tasks.qean.generate.generate_fast`) of ``generate_frames`` frames over its music.
It prints and writes into ``<log dir>/demo/``:

- the protocol table of ``sm test`` (FID_k / FID_g / Dist_k / Dist_g / BeatAlign, scored by
  :meth:`QEANModule.score_generated` against the demo set's real set), labelled NOT COMPARABLE with
  [QEAN] Table 1 (synthetic data, fewer and shorter sequences);
- the held-out dynamics of the generated frames (after the seed) beside their ground truth, the training
  mean pose and a random training sequence (:mod:`~skeleton_mamba.tasks.motion.metrics.held_out_dynamics`),
  with ``checks`` against the targets;
- ``conditioning``: the generated frames' beat margin over chance on the music's beats (the beat column of
  its FACT features: librosa's tracker) beside the ground truth's over the same frames
  (:mod:`~skeleton_mamba.tasks.motion.metrics.beat_conditioning`; target: at least half the truth's);
- ``synthetic_<sequence>_dance.{npz,bvh,glb,mp4,wav}``: the first ``num_samples`` dances (seed, then the
  generation) and ``synthetic_<sequence>_reference.*``: their ground truth over the same frames;
- ``demo.json``: what was done, with ``"synthetic": true``, the protocol figures, the dynamics and checks;
- ``view.html``: the first dance beside its ground truth, with the music (its path is printed).
"""

from __future__ import annotations

import warnings

from lightning.pytorch import LightningModule, Trainer

from skeleton_mamba.tasks.motion.formats.fact_features import FPS, features_to_joints
from skeleton_mamba.tasks.motion.metrics.beat_conditioning import conditioning_scores, format_conditioning
from skeleton_mamba.tasks.motion.metrics.held_out_dynamics import (
    format_dynamics,
    held_out_dynamics,
    held_out_dynamics_checks,
)
from skeleton_mamba.tasks.motion.music.features import beat_frames
from skeleton_mamba.tasks.motion.synthetic.aistpp_set import LABEL
from skeleton_mamba.tasks.qean.module import features_to_motion
from skeleton_mamba.tasks.training.demo_callback import DemoCallback, write_summary

__all__ = ["QEANDemo"]


class QEANDemo(DemoCallback):
    """Generate from the held-out seeds and music at the end of training, score and write the dances.

    Args:
        num_samples: held-out sequences whose dance (and ground truth) are written and rendered.
        out_subdir: folder under the trainer's log dir (:class:`DemoCallback`).
        render: write the renderings (a demo may take a format name instead of True).
        width: video width (multiple of 16).
        height: video height (multiple of 16).
    """

    def __init__(
        self,
        num_samples: int = 1,
        out_subdir: str = "demo",
        render: bool = True,
        width: int = 480,
        height: int = 352,
    ) -> None:
        super().__init__(out_subdir, render, width, height)
        self.num_samples = num_samples

    def on_fit_end(self, trainer: Trainer, pl_module: LightningModule) -> None:
        if not trainer.is_global_zero:
            return
        data = trainer.datamodule
        if not getattr(data, "synthetic", False):
            warnings.warn("QEANDemo: the data are not the SYNTHETIC demo set; no demo", stacklevel=2)
            return
        data.setup("test")
        seed_frames, generate_frames = data.seed_frames, data.generate_frames
        was_training = pl_module.training
        pl_module.eval()
        pl_module.on_test_epoch_start()  # the real set of the protocol table, the generated count reset
        names, generated, joints = [], [], []
        for batch in data.test_dataloader():
            full = pl_module.generate(batch["seed"].to(pl_module.device), batch["music"].to(pl_module.device))
            joints.extend(pl_module.score_generated(batch, full).cpu())  # (120 + G, 24, 3) each
            generated.extend(full.cpu())
            names.extend(batch["name"])
        protocol = pl_module.test_scores()
        if was_training:
            pl_module.train()
        length = seed_frames + generate_frames
        sequences = [data.sequence(name) for name in names]  # (motion (T, 219), music (T', 35)) each
        truths = [motion[:length] for motion, _ in sequences]  # (<= 120 + G, 219)
        train_motions = data.datasets["train"].sequences.values()
        train = [features_to_joints(motion.double()) for motion, _ in train_motions]
        dances = [j[seed_frames:] for j in joints]  # the generated frames, after the seed
        truth_joints = [features_to_joints(t[seed_frames:].double()) for t in truths]
        scores = held_out_dynamics(dances, truth_joints, train, FPS)
        checks = held_out_dynamics_checks(scores)
        beats = [beat_frames(music[seed_frames:length].numpy()) for _, music in sequences]  # after the seed
        conditioning = conditioning_scores(dances, truth_joints, beats, FPS)
        out = self.out_dir(trainer)
        records = []
        for name, dance, truth in list(zip(names, generated, truths, strict=True))[: self.num_samples]:
            motions = (
                ("dance", features_to_motion(dance), "QEAN dance from the seed (synthetic demo)"),
                ("reference", features_to_motion(truth), "ground truth (synthetic)"),
            )
            records.append(self.write_sample(out, name, data.music_file(name), motions))
        summary = {
            "synthetic": True,
            "label": LABEL,
            "held_out_split": "val",
            "global_step": trainer.global_step,
            "frames": {
                "seed": seed_frames,
                "music": data.music_frames,
                "predict": data.predict_frames,
                "generate": generate_frames,
            },
            "samples": records,
            "protocol": {
                "comparable_with_paper": False,
                "sequences": len(names),
                **protocol,
                "constant_real_features": pl_module.constant_real_features(),
            },
            "scores": {"held_out_sequences": len(names), "training_sequences": len(train), **scores},
            "checks": checks,
            "conditioning": conditioning,
        }
        view = write_summary(out, summary)
        lines = [
            f"[qean demo] {LABEL}",
            f"[qean demo] dances from held-out (val) seed motions and music -> {out}",
        ]
        for record in records:
            lines += [f"  {k}: {v}" for k, v in record["dance"].items()]
        lines += [
            pl_module.results_table(protocol),
            f"[qean demo] dynamics of the {generate_frames} generated frames, mean over {len(names)} "
            f"held-out sequences after {trainer.global_step} steps (baselines from the {len(train)} "
            "training sequences):",
            format_dynamics(scores, checks),
            format_conditioning(conditioning),
        ]
        if view is not None:
            lines.append(f"[qean demo] viewer: {view}")
        print("\n".join(lines), flush=True)
