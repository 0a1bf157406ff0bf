"""The live-dance demo's last act: after training, dance to held-out music frame by frame and score it.

:class:`StreamDanceDemo` is a Lightning callback (``stream_dance_demo.yaml`` configures it). When ``fit``
ends it takes the data module's held-out (``val``) sequences, music never danced to in training, and
dances to each with the trained network as ``sm stream`` does: one :meth:`StreamDancer.step` per 30 fps
frame, fed its own previous pose (no teacher forcing, no look-ahead). It writes into ``<log dir>/demo/``:

- ``synthetic_<sequence>_dance.{npz,bvh,glb,mp4,wav}``: the first ``num_samples`` dances (our motion
  format, BVH, glTF, a rendering with the music muxed in and that music), and
  ``synthetic_<sequence>_reference.*``: their ground truth;
- ``demo.json``: what was done, with ``"synthetic": true``, and ``scores``: motion amplitude and jitter of
  every scored dance as ratios to its ground truth's, beside the ground truth, the training mean pose and a
  random training sequence (:mod:`~skeleton_mamba.tasks.motion.metrics.held_out_dynamics`), with
  ``checks`` against the targets; ``conditioning``: the dances' beat margin over chance on their music's
  tracked beats beside their ground truth's
  (:mod:`~skeleton_mamba.tasks.motion.metrics.beat_conditioning`; target: at least half the truth's). The
  same is printed;
- ``view.html``: the first dance beside its ground truth, with the music, in a browser
  (:mod:`~skeleton_mamba.tasks.motion.render.view`; its path is printed).

Everything is labelled synthetic: the demo set's dances are procedural (on synthesised drum tracks, or on real
recordings' tracked beats with ``synthetic_music: recordings``).
"""

from __future__ import annotations

import warnings

import torch
from lightning.pytorch import LightningModule, Trainer

from skeleton_mamba.tasks.motion.formats.aistpp import music_id
from skeleton_mamba.tasks.motion.formats.fact_features import features_to_joints
from skeleton_mamba.tasks.motion.metrics.beat_conditioning import conditioning_scores, format_conditioning
from skeleton_mamba.tasks.motion.metrics.held_out_dynamics import (
    format_dynamics,
    held_out_dynamics,
    held_out_dynamics_checks,
)
from skeleton_mamba.tasks.motion.music.features import load_audio
from skeleton_mamba.tasks.motion.synthetic.aistpp_set import LABEL
from skeleton_mamba.tasks.motion.synthetic.recorded_music_set import tracked_beats
from skeleton_mamba.tasks.stream.features import FPS, HOP, SR
from skeleton_mamba.tasks.stream.model import (
    POSE_CHANNELS,
    StreamDancer,
    tokens_to_features,
    tokens_to_motion,
)
from skeleton_mamba.tasks.training.demo_callback import DemoCallback, write_summary

__all__ = ["StreamDanceDemo", "dance_to_features"]


@torch.no_grad()
def dance_to_features(model: StreamDancer, music: torch.Tensor) -> torch.Tensor:
    """Music features (T, 34) -> the dance (T, 24, 12), frame by frame on the network's own poses."""
    weight = next(model.parameters())
    prev = torch.zeros(1, 24, POSE_CHANNELS, dtype=weight.dtype, device=weight.device)
    state = model.init_state(1)
    poses = []
    for row in music.to(prev):
        prev, state = model.step(prev, row[None], state)
        poses.append(prev[0])
    return torch.stack(poses).cpu()


def _joints(tokens: torch.Tensor) -> torch.Tensor:
    """(T, 24, 12) tokens -> joints (T, 24, 3) in metres (forward kinematics of the 219-d vector)."""
    return features_to_joints(tokens_to_features(tokens.double()))


class StreamDanceDemo(DemoCallback):
    """Dance to the held-out music at the end of training, score and write it.

    Args:
        num_samples: held-out sequences whose dance (and ground truth) are written and rendered.
        score_samples: held-out sequences danced and scored (None: every one).
        seconds: dance to at most this much of each sequence's music (None: all of it).
        out_subdir: folder under the trainer's log dir (:class:`DemoCallback`).
        render: write the renderings (a demo may take a format name instead of True).
        width: video width (multiple of 16).
        height: video height (multiple of 16).
    """

    def __init__(
        self,
        num_samples: int = 1,
        score_samples: int | None = None,
        seconds: float | None = None,
        out_subdir: str = "demo",
        render: bool = True,
        width: int = 480,
        height: int = 352,
    ) -> None:
        if score_samples is not None and score_samples < 1:
            raise ValueError(
                f"score_samples must be at least 1 (or None: every sequence), got {score_samples}"
            )
        if seconds is not None and seconds * FPS < 3:
            raise ValueError(f"seconds must hold at least 3 frames at {FPS} fps, got {seconds}")
        self.num_samples = num_samples
        self.score_samples = score_samples
        self.seconds = seconds
        super().__init__(out_subdir, render, width, height)

    def on_fit_end(self, trainer: Trainer, pl_module: LightningModule) -> None:
        if not trainer.is_global_zero:
            return
        datasets = getattr(trainer.datamodule, "datasets", {}) or {}
        if "val" not in datasets or "train" not in datasets:
            warnings.warn(
                "StreamDanceDemo: the data module has no held-out (val) split; no demo", stacklevel=2
            )
            return
        held_out = datasets["val"].sequences  # name -> (tokens (T, 24, 12), music (T, 34))
        names = list(held_out)
        scored = len(names) if self.score_samples is None else min(self.score_samples, len(names))
        frames = None if self.seconds is None else round(self.seconds * FPS)
        out = self.out_dir(trainer)
        was_training = pl_module.training
        pl_module.eval()
        dances, truths, records, audios = [], [], [], []
        for i, name in enumerate(names[: max(scored, min(self.num_samples, len(names)))]):
            motion, music = (x[:frames] for x in held_out[name])
            tokens = dance_to_features(pl_module.model, music)
            dances.append(_joints(tokens))
            truths.append(_joints(motion))
            wav = trainer.datamodule.music_dir / f"{music_id(name)}.wav"
            audios.append(load_audio(wav, SR)[: len(music) * HOP])
            if i >= self.num_samples:
                continue
            motions = (
                ("dance", tokens_to_motion(tokens.float(), FPS), "live dance (synthetic demo)"),
                ("reference", tokens_to_motion(motion.float(), FPS), "ground truth (synthetic)"),
            )
            records.append(self.write_sample(out, name, wav, motions))
        if was_training:
            pl_module.train()
        train = [_joints(motion) for motion, _ in datasets["train"].sequences.values()]
        scores = held_out_dynamics(dances[:scored], truths[:scored], train, FPS)
        checks = held_out_dynamics_checks(scores)
        beats = [tracked_beats(audio) for audio in audios[:scored]]  # librosa's, at 30 fps
        conditioning = conditioning_scores(dances[:scored], truths[:scored], beats, FPS)
        label = getattr(trainer.datamodule, "label", LABEL)
        summary = {
            "synthetic": True,
            "label": label,
            "held_out_split": "val",
            "global_step": trainer.global_step,
            "samples": records,
            "scores": {"held_out_sequences": scored, "training_sequences": len(train), **scores},
            "checks": checks,
            "conditioning": conditioning,
        }
        view = write_summary(out, summary)
        lines = [f"[stream demo] {label}", f"[stream demo] live dance to held-out (val) music -> {out}"]
        for record in records:
            lines += [f"  {k}: {v}" for k, v in record["dance"].items()]
        lines += [
            f"[stream demo] scores, mean over {scored} held-out sequences after {trainer.global_step} steps "
            f"(baselines from the {len(train)} training sequences):",
            format_dynamics(scores, checks),
            format_conditioning(conditioning),
        ]
        if view is not None:
            lines.append(f"[stream demo] viewer: {view}")
        print("\n".join(lines), flush=True)
