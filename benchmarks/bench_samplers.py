"""Few-step samplers on a trained EgoMusic model: quality against deterministic DDIM over all T steps.

For every held-out window of the checkpoint's data, each sampler starts from the same noise (the window's
generator, as the demo seeds it) and samples with the checkpoint's guidance; the final dance is compared with
deterministic DDIM (eta 0) over every step of the model's schedule (T = 1000 for the paper's EMM, 100 for
the demo's) from that noise (mean joint distance, metres) and scored against the
ground truth as the demo scores it (MPJPE, BeatAlign, amplitude and jitter ratios), with the wall time per
window. ``--json`` prints the rows as JSON.

    python benchmarks/bench_samplers.py --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt --json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import time

import torch
from common import machine_info

from skeleton_mamba.tasks.egodance.data import data_module_from_hparams
from skeleton_mamba.tasks.egodance.demo_scores import score_held_out
from skeleton_mamba.tasks.egodance.module import EgoDanceModule
from skeleton_mamba.tasks.egodance.representation import motion_joints
from skeleton_mamba.tasks.motion.music import BEAT
from skeleton_mamba.tasks.training.checkpoints import load_module_and_checkpoint

CONFIGS = [("ddim", 50, 1.0), ("ddim", 50, 0.0)]
CONFIGS += [(solver, steps, 0.0) for solver in ("dpmpp", "unipc") for steps in (5, 10, 20)]


def held_out_batches(checkpoint: dict, limit: int) -> tuple[list[dict], list[torch.Tensor]]:
    """The first ``limit`` held-out windows of the checkpoint's data as batches of one, and the training
    windows' joints (the baselines' material)."""
    data = data_module_from_hparams(checkpoint["datamodule_hyper_parameters"])
    data.setup("fit")
    split = "test" if len(data.datasets.get("test", ())) else "val"
    dataset = data.datasets[split]
    batches = []
    for index in range(min(limit, len(dataset))):
        item = dataset[index]
        batches.append({k: v[None] for k, v in item.items() if torch.is_tensor(v)})
    train = [motion_joints(item["motion"]) for item in data.datasets["train"].items]
    return batches, train


def run(module, batches, sampler: str, steps: int, eta: float) -> tuple[list[torch.Tensor], float]:
    """Joints (T, 24, 3) of every window sampled by ``sampler`` and the median seconds per window."""
    module.sampling = dataclasses.replace(module.sampling, sampler=sampler, sampling_steps=steps, eta=eta)
    dances, seconds = [], []
    for index, batch in enumerate(batches):
        start = time.perf_counter()
        with torch.no_grad():
            tokens = module.sample(batch, index)[0]
        seconds.append(time.perf_counter() - start)
        dances.append(motion_joints(tokens.float()))
    return dances, statistics.median(seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ckpt", required=True, help="a trained egodance_demo.yaml checkpoint")
    parser.add_argument("--windows", type=int, default=4, help="held-out windows to sample")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    module, checkpoint = load_module_and_checkpoint(EgoDanceModule, args.ckpt)
    module.eval()
    batches, train = held_out_batches(checkpoint, args.windows)
    truths = [motion_joints(b["motion"][0].float()) for b in batches]
    beats = [b["music"][0, :, BEAT] for b in batches]
    reference_config = ("ddim", module.diffusion.num_steps, 0.0)  # every step of the schedule, no noise
    reference, reference_s = run(module, batches, *reference_config)
    rows = []
    for config in [reference_config, *CONFIGS]:
        sampler, steps, eta = config
        is_reference = config == reference_config
        dances, seconds = (reference, reference_s) if is_reference else run(module, batches, *config)
        scores = score_held_out(dances, truths, beats, train)["dance"]
        pairs = zip(dances, reference, strict=True)
        gap = statistics.mean(float((d - r).norm(dim=-1).mean()) for d, r in pairs)
        rows.append({
            "sampler": sampler, "steps": steps, "eta": eta, "seconds_per_window": round(seconds, 3),
            "to_ddim_all_steps_m": round(gap, 4), **{k: round(v, 4) for k, v in scores.items()},
        })  # fmt: skip
    result = {"machine": machine_info(), "checkpoint": args.ckpt, "windows": len(batches), "rows": rows}
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"# {result['machine']}; {len(batches)} held-out windows of {args.ckpt}")
    keys = list(rows[0])
    print(" | ".join(keys))
    for row in rows:
        print(" | ".join(str(row[k]) for k in keys))


if __name__ == "__main__":
    main()
