"""The text-to-motion demo's last act: after training, generate motions from prompts and render them.

:class:`TextToMotionDemo` is a Lightning callback (``humanml3d_demo.yaml`` configures it). When ``fit``
ends it samples one motion per prompt with the trained module and writes, into ``<log dir>/demo/``:

- ``synthetic_NN_<words>.npy`` (:func:`demo_stem`: the prompt's words without its ``synthetic:`` label,
  e.g. ``synthetic_00_a_person_waves_both_arms_up``): joint positions (T, 22, 3), metres, y-up, 20 fps
  (``sm render`` reads it);
- ``synthetic_NN_<words>_features.npy``: the 263-d HumanML3D features (T, 263);
- ``synthetic_NN_<words>.mp4`` (or ``.gif``): the rendering, titled with the prompt;
- ``demo.json``: prompts, sampler settings, paths, and ``"synthetic": true``, and ``scores``: motions
  generated for ``score_captions`` held-out captions (``score_samples`` each) scored against the training
  poses (:mod:`.demo_scores`: pose plausibility, and whether the caption matters), and ``dynamics``:
  their motion amplitude and jitter as ratios to the ground truth's (the held-out clip of the caption),
  beside the ground truth, the training mean pose and a random training clip
  (:mod:`~skeleton_mamba.tasks.motion.metrics.held_out_dynamics`), with ``checks``. The scores are printed;
- ``view.html``: the first scored motion beside its ground truth in a browser (:mod:`~skeleton_mamba.tasks.
  motion.view`; its path is printed).

The demo model was trained on SYNTHETIC captioned dances; the files, metadata and message say so.
"""

from __future__ import annotations

import dataclasses
import json
import re

import torch
from lightning.pytorch import LightningModule, Trainer

from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.skeletons import HUMANML3D22
from skeleton_mamba.tasks.motion.formats.gltf import from_joints
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FPS, recover_from_ric
from skeleton_mamba.tasks.motion.metrics.held_out_dynamics import (
    format_dynamics,
    held_out_dynamics,
    held_out_dynamics_checks,
)
from skeleton_mamba.tasks.motion.render.view import write_view
from skeleton_mamba.tasks.text2motion.actions import PARAPHRASES
from skeleton_mamba.tasks.text2motion.demo_scores import (
    action_checks,
    action_scores,
    caption_checks,
    caption_scores,
    format_action_scores,
    format_caption_scores,
)
from skeleton_mamba.tasks.text2motion.generate_cli import parse_length, save_generated, slug
from skeleton_mamba.tasks.text2motion.synthetic import LABEL as LABEL_PREFIX
from skeleton_mamba.tasks.training.demo_callback import DemoCallback
from skeleton_mamba.tasks.training.diffusion import SamplingOptions

__all__ = ["LABEL", "TextToMotionDemo", "demo_stem"]

LABEL = "model trained on SYNTHETIC captioned dances (procedural motions, template captions)"


def demo_stem(index: int, prompt: str) -> str:
    """``synthetic_NN_<words>``: the file stem of the demo's ``index``-th prompt, the words of the prompt
    without its leading ``synthetic:`` label (the stem's prefix says it once)."""
    words = re.sub(r"^\s*synthetic\b\s*:?\s*", "", prompt, flags=re.IGNORECASE)
    return f"synthetic_{index:02d}_{slug(words)}"


class TextToMotionDemo(DemoCallback):
    """Generate and render motions for prompts at the end of training.

    Args:
        prompts: captions to generate from.
        length: duration, ``"6s"`` (20 fps) or a frame count.
        out_subdir: folder under the trainer's log dir (``runs/<name>/version_N``).
        render: ``"mp4"``, ``"gif"`` or ``None`` (no video).
        sampler: ``"ddim"`` or ``"ddpm"`` (``None``: the module's).
        sampling_steps: DDIM steps (``None``: the module's; a number alone selects DDIM).
        seed: noise seed.
        score_captions: held-out captions (of the data module's val split) to score (0: no scores).
        score_samples: motions generated per scored caption (at least 2).
        action_samples: motions generated per paraphrased prompt of :data:`~.actions.PARAPHRASES` (0: none),
            each read back by :func:`~.actions.read_action` (:func:`~.demo_scores.action_scores`), when the
            data module's clips hold every action (``kinds``).
    """

    def __init__(
        self,
        prompts: list[str] | None = None,
        length: str = "6s",
        out_subdir: str = "demo",
        render: str | None = "mp4",
        sampling_steps: int | None = None,
        seed: int = 0,
        score_captions: int = 2,
        score_samples: int = 2,
        sampler: str | None = None,
        action_samples: int = 0,
    ) -> None:
        self.prompts = list(prompts or ["a person waves both arms up and down."])
        self.frames = parse_length(length)
        if render not in (None, "mp4", "gif"):
            raise ValueError(f"render must be 'mp4', 'gif' or null, got {render!r}")
        super().__init__(out_subdir, render)
        self.sampler = sampler
        self.sampling_steps = sampling_steps
        self.seed = seed
        if score_captions and (score_captions < 2 or score_samples < 2):
            raise ValueError("scoring needs score_captions >= 2 and score_samples >= 2 (or score_captions 0)")
        self.score_captions = score_captions
        self.score_samples = score_samples
        if action_samples < 0:
            raise ValueError(f"action_samples must be >= 0, got {action_samples}")
        self.action_samples = action_samples

    def on_fit_end(self, trainer: Trainer, pl_module: LightningModule) -> None:
        if not trainer.is_global_zero:
            return
        out = self.out_dir(trainer)
        was_training = pl_module.training
        pl_module.eval()
        sampling = pl_module.sampling.override(self.sampler, self.sampling_steps)
        features, _ = pl_module.generate(
            self.prompts,
            [self.frames] * len(self.prompts),
            generator=torch.Generator().manual_seed(self.seed),
            **dataclasses.asdict(sampling),
        )
        scored = self._score(trainer, pl_module, sampling)
        kinds = set(getattr(trainer.datamodule, "kinds", ()) or ())  # action scores: a set of every action
        acted = None
        if self.action_samples and kinds >= set(PARAPHRASES):
            acted = self._actions(pl_module, sampling)
        if was_training:
            pl_module.train()
        records = []
        for i, prompt in enumerate(self.prompts):
            stem = out / demo_stem(i, prompt)
            paths = save_generated(features[i], prompt, stem, self.render)
            records.append({"prompt": prompt, **{k: str(v) for k, v in paths.items()}})
        summary = {
            "synthetic": True,
            "label": LABEL,
            "frames": self.frames,
            "fps": 20,
            **sampling.describe(),
            "global_step": trainer.global_step,
            "samples": records,
        }
        if scored is not None:
            summary["scores"], summary["checks"], _ = scored
        if acted is not None:
            summary["actions"] = acted[0]
            summary["checks"] = {**summary.get("checks", {}), **acted[1]}
        out.mkdir(parents=True, exist_ok=True)
        with atomic_open(out / "demo.json", "w", encoding="utf-8") as f:
            f.write(json.dumps(summary, indent=2))
        lines = [f"[text2motion demo] {LABEL}", f"[text2motion demo] generated from prompts -> {out}"]
        for record in records:
            lines.append(f"  {record['prompt']!r}: {record.get('video', record['joints'])}")
        if scored is not None:
            scores, checks, (dance, truth) = scored
            caption_keys = ("plausibility_m", "within_caption_m", "between_captions_m")
            caption_checks_ = {k: v for k, v in checks.items() if k not in scores["dynamics"]["checks"]}
            lines += [
                f"[text2motion demo] {self.score_samples} motions for each of {len(scores['captions'])} "
                f"held-out captions after {trainer.global_step} steps: {scores['captions']}",
                format_caption_scores({k: scores[k] for k in caption_keys}, caption_checks_),
                "[text2motion demo] amplitude and jitter beside the held-out ground truth (baselines from "
                f"the {scores['dynamics']['training_clips']} training clips):",
                format_dynamics(scores["dynamics"]["columns"], scores["dynamics"]["checks"]),
            ]
            pair = (("generated", dance), ("ground truth", truth))
            motions = [(name, from_joints(j.numpy(), HUMANML3D22.name, FPS)) for name, j in pair]
            view = write_view(motions, out / "view.html", metrics=summary["scores"])
            lines.append(f"[text2motion demo] viewer: {view}")
        if acted is not None:
            lines += [
                f"[text2motion demo] does the motion show the prompt's action? {self.action_samples} "
                f"motion(s) for each of {len(acted[0]['prompts'])} prompts worded as no training caption is, "
                "the action read from the joints (pelvis height, path, heading, wrists, knees, ankles):",
                format_action_scores(acted[0], acted[1]),
            ]
        print("\n".join(lines), flush=True)

    def _actions(self, pl_module: LightningModule, sampling: SamplingOptions) -> tuple[dict, dict[str, bool]]:
        """Generate for every paraphrased prompt and read each motion's action back
        (:func:`~.demo_scores.action_scores`): ``(scores with the prompts, checks)``."""
        asked = [(action, LABEL_PREFIX + text) for action, texts in PARAPHRASES.items() for text in texts]
        prompts = [p for _, p in asked for _ in range(self.action_samples)]
        features, _ = pl_module.generate(
            prompts,
            [self.frames] * len(prompts),
            generator=torch.Generator().manual_seed(self.seed + 2),
            **dataclasses.asdict(sampling),
        )
        joints = list(recover_from_ric(features.detach().cpu().double()))
        expected = [a for a, _ in asked for _ in range(self.action_samples)]
        scores = action_scores(expected, joints)
        return {"prompts": [p for _, p in asked], **scores}, action_checks(scores)

    def _score(
        self, trainer: Trainer, pl_module: LightningModule, sampling: SamplingOptions
    ) -> tuple[dict, dict, tuple[torch.Tensor, torch.Tensor]] | None:
        """Generate for held-out captions and score them (:mod:`.demo_scores`, amplitude and jitter beside
        the caption's held-out clip): ``(scores, checks, (first motion, its truth))``; None: not scoring."""
        datasets = getattr(trainer.datamodule, "datasets", {}) or {}
        if not self.score_captions or "train" not in datasets or "val" not in datasets:
            return None
        truths: dict[str, torch.Tensor] = {}  # caption -> joints (T, 22, 3) of its first held-out clip
        for clip in datasets["val"].clips:
            if clip.captions[0].text not in truths:
                truths[clip.captions[0].text] = recover_from_ric(torch.from_numpy(clip.features).double())
        captions = list(truths)[: self.score_captions]
        if len(captions) < 2:
            return None
        prompts = [c for c in captions for _ in range(self.score_samples)]
        features, _ = pl_module.generate(
            prompts,
            [self.frames] * len(prompts),
            generator=torch.Generator().manual_seed(self.seed + 1),
            **dataclasses.asdict(sampling),
        )
        joints = recover_from_ric(features.detach().cpu().double())
        motions = {c: [joints[i] for i, p in enumerate(prompts) if p == c] for c in captions}
        train = [recover_from_ric(torch.from_numpy(c.features).double()) for c in datasets["train"].clips]
        scores = caption_scores(motions, torch.cat(train))
        dynamics = held_out_dynamics(list(joints), [truths[p] for p in prompts], train, FPS)
        dynamics_checks = held_out_dynamics_checks(dynamics)
        summary = {
            "captions": captions,
            **scores,
            "dynamics": {"training_clips": len(train), "columns": dynamics, "checks": dynamics_checks},
        }
        return summary, {**caption_checks(scores), **dynamics_checks}, (joints[0], truths[prompts[0]])
