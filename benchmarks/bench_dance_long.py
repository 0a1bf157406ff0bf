"""A whole song through ``sm dance``: music + egocentric video -> dance files, timed per stage.

Builds a random-weight EgoDance module of a recipe's architecture (``--size paper``: ``egodance.yaml``,
[EgoMusic] supp. Table 2, a random ResNet-50 at 224 px; ``--size demo``: ``egodance_demo.yaml``), saves it as
a checkpoint, writes a synthetic song (drums and bass, 120 BPM) and an egocentric video of ``--seconds`` at
30 fps, and runs ``sm dance --music --video`` itself (decoding, the music features, the vision encoder once
per frame, the head estimator, windowed sampling with in-painted overlaps, stitching, writing npz / BVH /
mp4). The seconds of every stage are the ones ``sm dance`` prints. Random weights time the work, not the
dance.

``ddpm1000_extrapolated_s`` is NOT a measured run: the sampling seconds per denoising step (all windows)
times 1000 (the recipe's ancestral DDPM), plus the other stages as measured.

    python benchmarks/bench_dance_long.py --size paper --seconds 60 --json
    python benchmarks/bench_dance_long.py --size demo --seconds 20 --sampler ddim --steps 50
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import sys
import tempfile
import time
import warnings
from pathlib import Path

import imageio.v3 as iio
import lightning
import numpy as np
import torch
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

from skeleton_mamba.tasks.egodance import dance_cli  # noqa: E402
from skeleton_mamba.tasks.egodance.module import EgoDanceModule  # noqa: E402
from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music  # noqa: E402
from skeleton_mamba.tasks.training.diffusion.solvers import FAST_SOLVER_STEPS  # noqa: E402

RECIPES = Path(__file__).resolve().parents[1] / "recipes"
SIZES = {"paper": "egodance.yaml", "demo": "egodance_demo.yaml"}


def recipe_module(recipe: str) -> EgoDanceModule:
    """The recipe's EgoDance module with random weights (its ResNet random too: no download)."""
    model = yaml.safe_load((RECIPES / recipe).read_text())["model"]["init_args"]
    backbone = model.get("backbone")
    if isinstance(backbone, str):
        backbone = yaml.safe_load((RECIPES / backbone).read_text()) or {}
    model = {**model, "backbone": backbone, "resnet_path": None}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the random ResNet's warning: timing only
        return EgoDanceModule(**model)


def write_inputs(folder: Path, seconds: float, size: int, fps: int = 30) -> tuple[Path, Path]:
    """A synthetic song and an egocentric video (a textured scene panning and bobbing) of ``seconds``."""
    wav = write_music(folder / "song.wav", synthesize_music(120.0, seconds))
    yy, xx = np.mgrid[0:size, 0:size] / size
    frames = []
    for i in range(int(round(seconds * fps))):
        t = i / fps
        u, v = xx + 0.2 * t, yy + 0.05 * np.sin(2 * np.pi * 2 * t)  # pan, bob on the beat
        rgb = np.stack([np.sin(9 * u) * np.cos(7 * v), np.sin(5 * u + 3 * v), np.cos(11 * v - 2 * u)], -1)
        frames.append(((rgb * 0.5 + 0.5) * 255).astype(np.uint8))
    video = folder / "ego.mp4"
    iio.imwrite(video, np.stack(frames), fps=fps, codec="libx264")
    return wav, video


def stage_seconds(output: str) -> dict[str, float]:
    """The seconds per stage ``sm dance`` printed."""
    line = re.search(r"seconds per stage: (.*)", output).group(1)
    return {name: float(value) for name, value in (part.rsplit(" ", 1) for part in line.split(", "))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", choices=sorted(SIZES), default="paper")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--sampler", default="dpmpp", help="sm dance --sampler (default: the fast path)")
    ap.add_argument("--steps", type=int, default=None, help="sm dance --steps (default: the sampler's)")
    ap.add_argument("--precision", default="fp32", choices=["fp32", "bf16"])
    ap.add_argument("--video-size", type=int, default=256, help="the synthetic video's frame size (px)")
    ap.add_argument("--no-render", action="store_true", help="skip the mp4 (sm dance --no-render)")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    module = recipe_module(SIZES[args.size])
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        ckpt = folder / "emm.ckpt"
        state = {"state_dict": module.state_dict(), "hyper_parameters": dict(module.hparams)}
        torch.save({**state, "pytorch-lightning_version": lightning.__version__}, ckpt)
        start = time.perf_counter()
        wav, video = write_inputs(folder, args.seconds, args.video_size)
        inputs_s = time.perf_counter() - start
        dance = ["--ckpt", str(ckpt), "--music", str(wav), "--video", str(video)]
        dance += ["--out", str(folder / "out")]
        dance += ["--sampler", args.sampler, "--precision", args.precision]
        dance += ["--steps", str(args.steps)] if args.steps else []
        dance += ["--no-render"] if args.no_render else []
        buffer = io.StringIO()
        start = time.perf_counter()
        with contextlib.redirect_stdout(buffer):
            dance_cli.main(dance)
        total_s = time.perf_counter() - start
    output = buffer.getvalue()
    stages = stage_seconds(output)
    windows = int(m.group(1)) if (m := re.search(r"(\d+) windows of", output)) else 1
    if args.steps:
        steps = args.steps
    elif args.sampler in ("dpmpp", "unipc"):
        steps = FAST_SOLVER_STEPS
    else:  # the checkpoint's: DDPM runs every diffusion step
        steps = module.diffusion.num_steps if args.sampler == "ddpm" else module.sampling.sampling_steps
    per_step = stages["sampling"] / steps
    result = {
        "machine": machine_info(),
        "threads": torch.get_num_threads(),
        "size": args.size,
        "seconds_of_music": args.seconds,
        "sampler": args.sampler,
        "steps": steps,
        "precision": args.precision,
        "windows": windows,
        "stages_s": stages,
        "sm_dance_total_s": round(total_s, 1),
        "sampling_s_per_step_all_windows": round(per_step, 2),
        "ddpm1000_extrapolated_s": round(total_s - stages["sampling"] + 1000 * per_step, 0),
        "inputs_written_s": round(inputs_s, 1),
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(output, end="")
        for key, value in result.items():
            print(f"{key}: {value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
