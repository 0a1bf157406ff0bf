"""Few-step samplers on a trained EgoMusic or text-to-motion model: quality against deterministic DDIM over
all T steps.

For every held-out window of the checkpoint's data, each sampler starts from the same noise (the window's
generator, as the demo seeds it) and samples with the checkpoint's guidance; the final dance is compared with
deterministic DDIM (eta 0) over every step of the model's schedule (T = 1000 for the paper's EMM, 100 for
the demo's) from that noise (mean joint distance, metres) and scored against the
ground truth as the demo scores it (MPJPE, BeatAlign, amplitude and jitter ratios), with the wall time per
window. ``--task text2motion``: a ``humanml3d_demo.yaml`` checkpoint, every held-out caption of the synthetic
set (6 s each, one motion per caption, the demo's seed), amplitude, jitter and energy above 6 Hz beside each
caption's held-out clip. DPM-Solver++ also runs with diffusers' default second-order last step
(``euler_at_final: false`` in its rows) beside ours (first order). ``--json`` prints the rows as JSON.

    python benchmarks/bench_samplers.py --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt --json
    python benchmarks/bench_samplers.py --task text2motion --windows 6 \
        --ckpt runs/humanml3d_demo/version_0/checkpoints/last.ckpt
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import statistics
import time

import torch
import yaml
from common import machine_info

from skeleton_mamba.tasks.egodance.data import data_module_from_hparams
from skeleton_mamba.tasks.egodance.demo_scores import score_held_out
from skeleton_mamba.tasks.egodance.module import EgoDanceModule
from skeleton_mamba.tasks.egodance.representation import motion_joints
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FPS, recover_from_ric
from skeleton_mamba.tasks.motion.metrics.held_out_dynamics import held_out_dynamics
from skeleton_mamba.tasks.motion.music.features import BEAT
from skeleton_mamba.tasks.text2motion.data import SyntheticTextMotionDataModule
from skeleton_mamba.tasks.text2motion.module import TextToMotionModule
from skeleton_mamba.tasks.training.checkpoints import load_module, load_module_and_checkpoint
from skeleton_mamba.tasks.training.diffusion.solvers import SOLVERS
from skeleton_mamba.tasks.training.recipe_resolution import packaged_recipe_dir

CONFIGS = [("ddim", 50, 1.0), ("ddim", 50, 0.0)]
CONFIGS += [(solver, steps, 0.0) for solver in ("dpmpp", "unipc") for steps in (5, 10, 20)]
SECOND_ORDER_FINAL = [("dpmpp", steps, 0.0) for steps in (5, 10, 20)]
"""DPM-Solver++ with a second-order last step (diffusers' default, ``euler_at_final=False``) beside ours."""


@contextlib.contextmanager
def dpmpp_options(**options):
    """DPM-Solver++ with ``options`` replacing its scheduler options while inside."""
    saved = SOLVERS["dpmpp"]
    SOLVERS["dpmpp"] = (saved[0], {**saved[1], **options})
    try:
        yield
    finally:
        SOLVERS["dpmpp"] = saved


class EgoMusicCase:
    """The first ``limit`` held-out windows of an EMM checkpoint's data, scored as the EgoMusic demo does."""

    unit = "window"

    def __init__(self, ckpt: str, limit: int) -> None:
        self.module, checkpoint = load_module_and_checkpoint(EgoDanceModule, ckpt)
        self.module.eval()
        data = data_module_from_hparams(checkpoint["datamodule_hyper_parameters"])
        data.setup("fit")
        dataset = data.datasets["test" if len(data.datasets.get("test", ())) else "val"]
        self.batches = []
        for index in range(min(limit, len(dataset))):
            item = dataset[index]
            self.batches.append({k: v[None] for k, v in item.items() if torch.is_tensor(v)})
        self.truths = [motion_joints(b["motion"][0].float()) for b in self.batches]
        self.beats = [b["music"][0, :, BEAT] for b in self.batches]
        self.train = [motion_joints(item["motion"]) for item in data.datasets["train"].items]
        self.num_steps = self.module.diffusion.num_steps

    def sample(self, sampler: str, steps: int, eta: float) -> tuple[list[torch.Tensor], float]:
        """Joints (T, 24, 3) of every window and the median seconds per window."""
        module = self.module
        module.sampling = dataclasses.replace(module.sampling, sampler=sampler, sampling_steps=steps, eta=eta)
        dances, seconds = [], []
        for index, batch in enumerate(self.batches):
            start = time.perf_counter()
            with torch.no_grad():
                tokens = module.sample(batch, index)[0]
            seconds.append(time.perf_counter() - start)
            dances.append(motion_joints(tokens.float()))
        return dances, statistics.median(seconds)

    def score(self, dances: list[torch.Tensor]) -> dict[str, float]:
        return score_held_out(dances, self.truths, self.beats, self.train)["dance"]


class TextToMotionCase:
    """The held-out captions of a ``humanml3d_demo.yaml`` checkpoint's synthetic set, a 6 s motion each, with
    amplitude, jitter and energy above 6 Hz beside each caption's held-out clip."""

    unit = "caption"

    def __init__(self, ckpt: str, limit: int) -> None:
        self.module = load_module(TextToMotionModule, ckpt)
        self.module.eval()
        recipe = yaml.safe_load((packaged_recipe_dir() / "humanml3d_demo.yaml").read_text())
        data = SyntheticTextMotionDataModule(**recipe["data"]["init_args"])
        data.setup("fit")
        truths: dict[str, torch.Tensor] = {}
        for clip in data.datasets["val"].clips:
            truths.setdefault(
                clip.captions[0].text, recover_from_ric(torch.from_numpy(clip.features).double())
            )
        self.captions = list(truths)[:limit]
        self.truths = [truths[c] for c in self.captions]
        self.train = [
            recover_from_ric(torch.from_numpy(c.features).double()) for c in data.datasets["train"].clips
        ]
        self.num_steps = self.module.diffusion.num_steps

    def sample(self, sampler: str, steps: int, eta: float) -> tuple[list[torch.Tensor], float]:
        """Joints (T, 22, 3) for every caption (one batch) and the seconds per caption."""
        start = time.perf_counter()
        features, _ = self.module.generate(
            self.captions,
            [6 * FPS] * len(self.captions),
            generator=torch.Generator().manual_seed(1),
            sampler=sampler,
            sampling_steps=steps,
            eta=eta,
        )
        seconds = (time.perf_counter() - start) / len(self.captions)
        return list(recover_from_ric(features.detach().cpu().double()).float()), seconds

    def score(self, motions: list[torch.Tensor]) -> dict[str, float]:
        return held_out_dynamics([m.double() for m in motions], self.truths, self.train, FPS)["dance"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", choices=("egodance", "text2motion"), default="egodance")
    parser.add_argument(
        "--ckpt", required=True, help="a trained egodance_demo.yaml / humanml3d_demo.yaml checkpoint"
    )
    parser.add_argument("--windows", type=int, default=4, help="held-out windows (captions) to sample")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    case = (EgoMusicCase if args.task == "egodance" else TextToMotionCase)(args.ckpt, args.windows)
    reference_config = ("ddim", case.num_steps, 0.0)  # every step of the schedule, no noise
    reference, reference_s = case.sample(*reference_config)
    rows = []
    configs = [(c, {}) for c in [reference_config, *CONFIGS]]
    configs += [(c, {"euler_at_final": False}) for c in SECOND_ORDER_FINAL]
    for config, options in configs:
        sampler, steps, eta = config
        is_reference = config == reference_config
        with dpmpp_options(**options):
            motions, seconds = (reference, reference_s) if is_reference else case.sample(*config)
        scores = case.score(motions)
        pairs = zip(motions, reference, strict=True)
        gap = statistics.mean(float((m - r).norm(dim=-1).mean()) for m, r in pairs)
        rows.append({
            "sampler": sampler, "steps": steps, "eta": eta, f"seconds_per_{case.unit}": round(seconds, 3),
            "to_ddim_all_steps_m": round(gap, 4), **{k: round(v, 4) for k, v in scores.items()},
            **({"euler_at_final": options["euler_at_final"]} if options else {}),
        })  # fmt: skip
    count = len(reference)
    result = {"machine": machine_info(), "checkpoint": args.ckpt, f"{case.unit}s": count, "rows": rows}
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"# {result['machine']}; {count} held-out {case.unit}s of {args.ckpt}")
    keys = list(rows[0])
    print(" | ".join(keys))
    for row in rows:
        print(
            " | ".join(str(row[k]) for k in keys)
            + (" | second-order last step" if "euler_at_final" in row else "")
        )


if __name__ == "__main__":
    main()
