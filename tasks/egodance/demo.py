"""The demo's last act: after training, dance to held-out music and egocentric video and render it.

:class:`DanceDemo` is a Lightning callback (``egodance_demo.yaml`` configures it). When ``fit`` ends it
takes the first ``num_samples`` windows of the data module's held-out split (``test``, else ``val``:
motion sources never seen in training), samples a dance with the EMA model for each window's music,
egocentric frames and head-camera trajectory, and writes into ``<log dir>/demo/``:

- ``synthetic_<sample id>_dance.{npz,bvh,mp4,wav}`` (paths in ``demo.json`` are as written: relative to the
  working directory when the log dir is): the sampled dance (our motion format, BVH, a
  rendering with the window's music muxed in, and that music slice);
- ``synthetic_<sample id>_reference.{npz,bvh,mp4,wav}``: the ground-truth dance of the window, for
  comparison (``render_reference``);
- ``synthetic_long_<dance>_dance.{npz,bvh,mp4,wav}``: a held-out dance of ``long_sample_s`` seconds (a
  minute) danced long-form from its music and egocentric video (:mod:`.long_demo`);
- ``demo.json``: what was done, with ``"synthetic": true`` and the data's provenance, and ``scores``: every
  held-out window's dance scored beside its ground truth and two baselines (:mod:`.demo_scores`: pose
  plausibility, MPJPE, BeatAlign, foot skating, ground penetration), with ``checks`` against the targets;
  ``long_form``: the long dance's scores (whole-sequence MPJPE beside its windows sampled alone and the
  mean pose, the seams: :mod:`.long_form_scores`), its checks joining the others. The same tables are
  printed.

Everything is labelled synthetic (file names, metadata, the printed message and the video title): the
demo data are procedural dances and synthesised music placed in procedural rooms.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import torch
from lightning.pytorch import LightningModule, Trainer

from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.tasks.egodance.builder.layout import read_meta
from skeleton_mamba.tasks.egodance.demo_scores import format_scores, score_held_out, target_checks
from skeleton_mamba.tasks.egodance.export import write_dance
from skeleton_mamba.tasks.egodance.long_demo import format_long_scores, long_sample, score_long_dance
from skeleton_mamba.tasks.egodance.representation import motion_joints
from skeleton_mamba.tasks.motion.formats.motion_reader import load_skeleton_motion
from skeleton_mamba.tasks.motion.music.features import BEAT
from skeleton_mamba.tasks.motion.render.view import write_view
from skeleton_mamba.tasks.training.demo_callback import DemoCallback

__all__ = ["DanceDemo"]

LABEL = "SYNTHETIC demo data (procedural dances, synthesised music, procedural rooms)"


class DanceDemo(DemoCallback):
    """Sample and render dances for held-out windows at the end of training.

    Args:
        num_samples: held-out windows to dance to and render.
        score_samples: held-out windows to sample and score (None: all of them).
        out_subdir: folder under the trainer's log dir (``runs/<name>/version_N``).
        render: write the mp4 renderings.
        render_reference: also write the ground-truth dance of each window.
        width: video width (multiple of 16).
        height: video height (multiple of 16).
        long_sample_s: seconds of the held-out long dance danced long-form (0: none; generated data only).
    """

    def __init__(
        self,
        num_samples: int = 1,
        score_samples: int | None = None,
        out_subdir: str = "demo",
        render: bool = True,
        render_reference: bool = True,
        width: int = 480,
        height: int = 352,
        long_sample_s: float = 60.0,
    ):
        self.num_samples = num_samples
        if score_samples is not None and score_samples < 1:
            raise ValueError(f"score_samples must be at least 1 (or None: every window), got {score_samples}")
        self.score_samples = score_samples
        super().__init__(out_subdir, render, width, height)
        self.render_reference = render_reference
        if not long_sample_s >= 0:
            raise ValueError(f"long_sample_s must be >= 0 seconds, got {long_sample_s}")
        self.long_sample_s = long_sample_s

    @staticmethod
    def _held_out(trainer: Trainer):
        datasets = getattr(trainer.datamodule, "datasets", {}) or {}
        for split in ("test", "val"):
            if split in datasets and len(datasets[split]) > 0:
                return split, datasets[split]
        return None, None

    def _long_song(self, trainer: Trainer, pl_module, dataset, train: list[torch.Tensor], out: Path):
        """The long held-out dance's scores and files (:mod:`.long_demo`), or None (off, or not the
        generated set)."""
        data = trainer.datamodule
        if self.long_sample_s <= 0 or not hasattr(data, "source_root"):
            return None
        meta = read_meta(dataset.folders[0])
        source = (meta.get("motion") or {}).get("source") or ""
        folder = long_sample(data, source, self.long_sample_s)
        mean_pose = torch.cat([clip.reshape(-1, *clip.shape[-2:]) for clip in train]).mean(0)
        tokens, inputs, scores = score_long_dance(pl_module, folder, mean_pose)
        files = write_dance(
            tokens,
            out,
            f"synthetic_long_{Path(source).stem.removeprefix('synthetic_')}_dance",
            music=inputs.music_path,
            music_start_s=inputs.music_start_s,
            render=self.render,
            style=self.style,
            title="EMM, long-form (synthetic demo)",
        )
        return {**scores, "files": {k: str(v) for k, v in vars(files).items() if v is not None}}

    def on_fit_end(self, trainer: Trainer, pl_module: LightningModule) -> None:
        if not trainer.is_global_zero:
            return
        split, dataset = self._held_out(trainer)
        if dataset is None:
            warnings.warn(
                "DanceDemo: the data module has no held-out (test/val) window; no demo dance", stacklevel=2
            )
            return
        out = self.out_dir(trainer)
        was_training = pl_module.training
        pl_module.eval()
        records, dances, truths, beats = [], [], [], []
        scored = len(dataset) if self.score_samples is None else min(self.score_samples, len(dataset))
        for index in range(max(min(self.num_samples, len(dataset)), scored)):
            item = dataset[index]
            batch = {k: v[None].to(pl_module.device) for k, v in item.items() if torch.is_tensor(v)}
            with torch.no_grad():
                tokens = pl_module.sample(batch, index)[0].cpu()
            dances.append(motion_joints(tokens))
            truths.append(motion_joints(item["motion"]))
            beats.append(item["music"][:, BEAT])
            if index >= self.num_samples:
                continue
            meta = read_meta(dataset.folders[index])
            music = meta.get("music") or {}
            sid = str(item["sample_id"])
            name = sid if sid.startswith("synthetic") else f"synthetic_{sid}"
            written = {"dance": (tokens, f"{name}_dance", "EMM (synthetic demo)")}
            if self.render_reference:
                written["reference"] = (item["motion"], f"{name}_reference", "ground truth (synthetic)")
            record = {"sample_id": sid, "split": split, "music": music}
            for kind, (motion, stem, title) in written.items():
                files = write_dance(
                    motion,
                    out,
                    stem,
                    music=music.get("path"),
                    music_start_s=float(music.get("start_s", 0.0)),
                    render=self.render,
                    style=self.style,
                    title=title,
                )
                record[kind] = {k: str(v) for k, v in vars(files).items() if v is not None}
            records.append(record)
        train = [motion_joints(item["motion"]) for item in trainer.datamodule.datasets["train"].items]
        scores = score_held_out(dances[:scored], truths[:scored], beats[:scored], train)
        checks = target_checks(scores)
        long_form = self._long_song(trainer, pl_module, dataset, train, out)
        if long_form is not None:
            checks.update({f"long song: {k}": v for k, v in long_form["checks"].items()})
        summary = {
            "synthetic": True,
            "label": LABEL,
            "held_out_split": split,
            "sampler": pl_module.sampling.sampler,
            "sampling_steps": pl_module.sampling.sampling_steps,
            "guidance_weight": pl_module.sampling.guidance_weight,
            "global_step": trainer.global_step,
            "samples": records,
            "scores": {"held_out_windows": scored, "training_windows": len(train), **scores},
            "long_form": long_form,
            "checks": checks,
        }
        with atomic_open(out / "demo.json", "w", encoding="utf-8") as f:
            f.write(json.dumps(summary, indent=2))
        if was_training:
            pl_module.train()
        lines = [f"[egodance demo] {LABEL}", f"[egodance demo] dance for held-out ({split}) music -> {out}"]
        for record in records:
            lines += [f"  {k}: {v}" for k, v in record["dance"].items()]
        lines += [
            f"[egodance demo] scores, mean over {scored} held-out ({split}) windows after "
            f"{trainer.global_step} steps (baselines from the {len(train)} training windows):",
            format_scores(scores, {k: v for k, v in checks.items() if not k.startswith("long song: ")}),
        ]
        if long_form is not None:
            lines += [
                f"[egodance demo] long song: a held-out dance of {long_form['seconds']:.0f} s danced as "
                f"{long_form['windows']} windows from its music and egocentric video -> "
                f"{long_form['files']['npz']}",
                format_long_scores(long_form),
            ]
        if records and "reference" in records[0]:  # the first dance beside its ground truth, in a browser
            first = records[0]
            motions = [(kind, load_skeleton_motion(first[kind]["npz"])) for kind in ("dance", "reference")]
            view = write_view(motions, out / "view.html", first["dance"].get("wav"), summary["scores"])
            lines.append(f"[egodance demo] viewer: {view}")
        print("\n".join(lines), flush=True)
