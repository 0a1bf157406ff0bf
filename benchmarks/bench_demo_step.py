"""The EgoMusic demo's training step (``recipes/egodance_demo.yaml``): steps per second and where they go.

Builds the recipe's EgoDanceModule (tiny backbone, tiny random ResNet, head-trajectory estimator) and a
batch of the recipe's shape (4 windows of 150 frames: motion tokens, 35 music features, frames at the
recipe's ``image_size`` (32 px), head targets; random values, which cost the same as real ones), with the
process settings ``sm fit`` uses (one thread by default on a small machine, the training allocator
settings of :mod:`skeleton_mamba.runtime.allocator` where the installed version has them), then
times, median over ``--repeats``:

- ``train_step_ms``: what Lightning runs per step: the module's ``training_step`` (EMM diffusion, kinematic
  and alignment losses + the estimator's loss), backward, AdamW; ``steps_per_s`` from it;
- ``vision_encoder_ms``, ``head_estimator_ms``: forward + backward of each alone on the batch's frames;
- ``--profile N``: the N operators with the most self CPU time over 3 steps;
- ``page_faults_per_step``, ``system_ms_per_step``: minor page faults and kernel time per step.

Before and after a change, side by side:
``python benchmarks/side_by_side.py --before REV -- bench_demo_step.py``.

    flock /tmp/bench.lock python benchmarks/bench_demo_step.py --json
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import warnings
from pathlib import Path

import torch
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, median_ms, operator_profile  # noqa: E402

from skeleton_mamba.tasks.egodance.module import EgoDanceModule  # noqa: E402
from skeleton_mamba.tasks.egodance.representation import NUM_CHANNELS, NUM_JOINTS  # noqa: E402
from skeleton_mamba.tasks.motion.music.features import NUM_MUSIC_FEATURES  # noqa: E402
from skeleton_mamba.tasks.training.recipe_resolution import packaged_recipe_dir  # noqa: E402
from skeleton_mamba.tasks.training.threads import apply_thread_defaults  # noqa: E402

try:  # what `sm fit` sets, where this version has it (a side-by-side run may time an older one)
    from skeleton_mamba.runtime.allocator import keep_freed_memory
except ImportError:
    keep_freed_memory = None


def build_module() -> tuple[EgoDanceModule, dict]:
    """The demo recipe's module (image size linked from its data section, as ``sm fit`` links it) and its
    data settings; the module turns the recipe's plain mappings into its config dataclasses itself."""
    recipes = packaged_recipe_dir()
    recipe = yaml.safe_load((recipes / "egodance_demo.yaml").read_text())
    args = dict(recipe["model"]["init_args"])
    data = recipe["data"]["init_args"]
    args["backbone"] = yaml.safe_load((recipes / args["backbone"]).read_text())
    args["image_size"] = data["image_size"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the random (not pretrained) ResNet
        module = EgoDanceModule(**args)
    module.log = module.log_dict = lambda *a, **k: None  # no trainer attached
    return module, data


def demo_batch(data: dict, frames: int = 150, generator: torch.Generator | None = None) -> dict:
    """A batch shaped as the demo's loader gives it (contiguous frames in [0, 1])."""
    b, s = data["batch_size"], data["image_size"]
    g = generator or torch.Generator().manual_seed(0)
    rotation = torch.eye(3).expand(b, frames, 3, 3).contiguous()
    return {
        "motion": torch.randn(b, frames, NUM_JOINTS, NUM_CHANNELS, generator=g) * 0.5,
        "music": torch.randn(b, frames, NUM_MUSIC_FEATURES, generator=g),
        "frames": torch.rand(b, frames, 3, s, s, generator=g),
        "head": torch.randn(b, frames, 3, generator=g) * 0.1 + torch.tensor([0.0, 1.6, 0.0]),
        "head_rotation": rotation,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--threads", type=int, default=None, help="default: as sm (threads.py)")
    ap.add_argument("--profile", type=int, default=0, metavar="N")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    else:
        apply_thread_defaults()
    allocator = bool(keep_freed_memory and keep_freed_memory())
    torch.manual_seed(0)
    module, data = build_module()
    batch = demo_batch(data)
    optimizer = torch.optim.AdamW(module.parameters(), lr=1e-3)

    def train_step() -> None:
        optimizer.zero_grad(set_to_none=True)
        module.training_step(batch, 0).backward()
        optimizer.step()

    def vision() -> None:
        module.model.vision_encoder(batch["frames"]).square().mean().backward()

    def head() -> None:
        positions, rotations = module.head_estimator(batch["frames"])
        (positions.square().mean() + rotations.square().mean()).backward()

    train_step()
    train_step()
    before = resource.getrusage(resource.RUSAGE_SELF)
    step_ms = median_ms(train_step, args.repeats, warmup=0)
    after = resource.getrusage(resource.RUSAGE_SELF)
    result = {
        "machine": machine_info(),
        "threads": torch.get_num_threads(),
        "training_allocator": allocator,
        "batch": {k: list(v.shape) for k, v in batch.items()},
        "train_step_ms": round(step_ms, 1),
        "steps_per_s": round(1e3 / step_ms, 2),
        "page_faults_per_step": round((after.ru_minflt - before.ru_minflt) / args.repeats),
        "system_ms_per_step": round((after.ru_stime - before.ru_stime) * 1e3 / args.repeats, 1),
        "vision_encoder_ms": round(median_ms(vision, args.repeats), 1),
        "head_estimator_ms": round(median_ms(head, args.repeats), 1),
    }
    if args.profile:
        table, gemm_share = operator_profile(lambda: [train_step() for _ in range(3)], args.profile)
        print(table, file=sys.stderr)
        result["matrix_product_share"] = round(gemm_share, 3)
    print(json.dumps(result, indent=2) if args.json else "\n".join(f"{k}: {v}" for k, v in result.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
