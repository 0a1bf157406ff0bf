"""EgoAIST++ builder benchmark: ray-cast rendering speed and end-to-end build time.

    python benchmarks/bench_egobuilder.py [--json] [--workers 2] [--frames 120] [--motion-seconds 20]

1. Rendering: frames per second of egocentric RGB + depth at 224 x 224 along a dancing head trajectory in a
   procedural room, with 1 process and with ``--workers`` processes (frames split between them).
2. End to end: ``sm make-ego`` (placement, penetration, rendering, mp4 + depth writing) on a synthetic
   dance of ``--motion-seconds`` in procedural rooms, reported as seconds of build per minute of motion.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

from skeleton_mamba.tasks.egodance.builder.build import BuildConfig, run_build  # noqa: E402
from skeleton_mamba.tasks.egodance.builder.camera import CameraTrajectory, head_camera, intrinsics, pixel_rays  # noqa: E402
from skeleton_mamba.tasks.egodance.builder.placement import Placement, place_points  # noqa: E402
from skeleton_mamba.tasks.egodance.builder.procedural_scene import procedural_room  # noqa: E402
from skeleton_mamba.tasks.egodance.builder.raycast import TriangleCache, render_view  # noqa: E402
from skeleton_mamba.tasks.motion.motion_file import save_motion  # noqa: E402
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance  # noqa: E402


def _trajectory(frames: int, size: int) -> CameraTrajectory:
    """A head camera following a synthetic dance in the middle of procedural room 0."""
    import torch

    from skeleton_mamba.skeletons import SMPL24
    from skeleton_mamba.tasks.motion.kinematics import forward_kinematics
    from skeleton_mamba.tasks.motion.rotations import axis_angle_to_matrix
    from skeleton_mamba.tasks.motion.smpl import smpl_rest_offsets

    motion = synthesize_dance(120, frames / 30, 30, "arms", 0)
    local = axis_angle_to_matrix(torch.from_numpy(motion.poses).double())
    root = torch.from_numpy(motion.root_position()).double()
    joints, world = forward_kinematics(local, root, smpl_rest_offsets(torch.float64), SMPL24.parents)
    placement = Placement(yaw=0.7, translation=(0.0, 0.0, 0.0))
    placed = place_points(joints.numpy(), placement)
    K = intrinsics(size, size, 90.0)
    return head_camera(placed[:, 15], placement.rotation @ world.numpy()[:, 15], K, size, size)


_STATE: dict = {}


def _init_renderer(total: int) -> None:
    """Worker initialiser: build the scene, the trajectory and the triangle cache once (not timed)."""
    scene = procedural_room(0)
    _STATE.update(scene=scene, cam=_trajectory(total, 224), cache=TriangleCache(scene))
    render_view(scene, _STATE["cam"].positions[0], _STATE["cam"].rotations[0], _STATE["cam"].K, 224, 224)


def _render_chunk(bounds: tuple[int, int]) -> int:
    scene, cam, cache = _STATE["scene"], _STATE["cam"], _STATE["cache"]
    rays = pixel_rays(cam.K, cam.width, cam.height)
    for i in range(*bounds):
        render_view(scene, cam.positions[i], cam.rotations[i], cam.K, 224, 224, rays=rays, cache=cache)
    return bounds[1] - bounds[0]


def bench_render(frames: int, workers: int) -> dict:
    """Frames per second of rendering only (scene loading and trajectory excluded)."""
    _init_renderer(frames)
    start, cpu = time.perf_counter(), time.process_time()
    _render_chunk((0, frames))
    single = frames / (time.perf_counter() - start)
    per_cpu_second = frames / (time.process_time() - cpu)  # less sensitive to other load on the machine
    bounds = np.linspace(0, frames, workers + 1).astype(int)
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(
        workers, mp_context=context, initializer=_init_renderer, initargs=(frames,)
    ) as pool:
        list(pool.map(_render_chunk, [(0, 1)] * workers))  # wait until every worker is initialised
        start = time.perf_counter()
        done = sum(pool.map(_render_chunk, list(zip(bounds[:-1], bounds[1:]))))
        elapsed = time.perf_counter() - start
    return {
        "frames": frames,
        "fps_1_process": single,
        "frames_per_cpu_second_1_process": per_cpu_second,
        f"fps_{workers}_processes": done / elapsed,
    }


def bench_build(seconds: float, workers: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        motion = save_motion(
            Path(tmp) / "synthetic_bounce_120bpm_s0.npz", synthesize_dance(120, seconds, 60, "bounce")
        )
        cfg = BuildConfig(
            out=str(Path(tmp) / "ego"), scenes="procedural", num_rooms=2, workers=workers, progress=False
        )
        start = time.perf_counter()
        summary = run_build(cfg, motion)
        elapsed = time.perf_counter() - start
    windows = summary.placed + summary.skipped
    return {
        "motion_seconds": seconds,
        "windows": windows,
        "placed": summary.placed,
        "rejected_placements": summary.rejected,
        "build_seconds": elapsed,
        "build_seconds_per_motion_minute": elapsed / (windows * cfg.window_s / 60.0),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--frames", type=int, default=120, help="frames rendered in the rendering benchmark")
    p.add_argument("--motion-seconds", type=float, default=20.0, help="length of the end-to-end motion")
    args = p.parse_args(argv)
    result = {
        "machine": machine_info(),
        "resolution": [224, 224],
        "render": bench_render(args.frames, args.workers),
        "build": bench_build(args.motion_seconds, args.workers),
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        r, b = result["render"], result["build"]
        print(f"machine: {result['machine']}")
        print(
            f"render 224x224: {r['fps_1_process']:.1f} fps (1 process), "
            f"{r[f'fps_{args.workers}_processes']:.1f} fps ({args.workers} processes)"
        )
        print(
            f"build: {b['build_seconds']:.1f} s for {b['windows']} windows of 5 s "
            f"-> {b['build_seconds_per_motion_minute']:.1f} s per minute of motion"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
