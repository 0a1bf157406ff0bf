"""EgoAIST++ builder benchmark: ray-cast rendering speed and end-to-end build time.

    python benchmarks/bench_egobuilder.py [--json] [--workers 2] [--frames 120] [--motion-seconds 20]
        [--repeats 3] [--smpl-model PATH] [--only-memory] [--scene MESH] [--rss-window 1] [--rss-timeout S]

1. Rendering: frames per second of egocentric RGB + depth at 224 x 224 along a dancing head trajectory in a
   procedural room, with 1 process and with ``--workers`` processes (frames split between them); the
   median of ``--repeats`` runs, plus frames per CPU-second of the single process (less sensitive to
   other load on a shared machine).
2. End to end: ``sm make-ego`` (placement, penetration, rendering, mp4 + depth writing) on a synthetic
   dance of ``--motion-seconds`` in procedural rooms with ``--workers`` processes, reported as seconds of
   build per minute of motion: with the capsule body, and with an SMPL mesh (``--smpl-model``, or by
   default a synthetic SMPL-format model of SMPL's size, 6890 vertices on capsule surfaces along the
   bones, since the real model cannot be distributed).
3. Peak memory (``--only-memory`` runs this alone): the peak resident set size of ``sm make-ego`` (its
   own process, 1 worker; the kernel's ``ru_maxrss`` of that child) with each ray caster
   (``SKELETON_MAMBA_RAY_CASTER=embree`` and ``trimesh``), on the EgoMusic demo's data (a generated dance
   in 2 procedural rooms at 64 x 64, twice the side ``egodance_demo.yaml`` builds) and on a real scene mesh at
   256 x 256 (``--scene``, default ``../shared/data/scenes/simple_room.glb``, z-up). One motion of
   ``--rss-window`` seconds keeps the slow fallback short; windows are built one after another, so the
   peak does not grow with their number.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info  # noqa: E402

from skeleton_mamba.tasks.egodance.builder.build import BuildConfig, run_build  # noqa: E402
from skeleton_mamba.tasks.egodance.builder.camera import CameraTrajectory, head_camera, intrinsics  # noqa: E402
from skeleton_mamba.tasks.egodance.builder.placement import Placement, place_points  # noqa: E402
from skeleton_mamba.tasks.egodance.builder.procedural_scene import procedural_room  # noqa: E402
from skeleton_mamba.tasks.egodance.builder.raycast import Renderer  # noqa: E402
from skeleton_mamba.tasks.motion.formats.motion_file import save_motion  # noqa: E402
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance  # noqa: E402


def _trajectory(frames: int, size: int) -> CameraTrajectory:
    """A head camera following a synthetic dance in the middle of procedural room 0."""
    import torch

    from skeleton_mamba.skeletons import SMPL24
    from skeleton_mamba.tasks.motion.body.kinematics import forward_kinematics
    from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix
    from skeleton_mamba.tasks.motion.body.smpl import smpl_rest_offsets

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
    """Worker initialiser: build the scene, the trajectory and the renderer once (not timed)."""
    import torch

    torch.set_num_threads(1)
    scene = procedural_room(0)
    cam = _trajectory(total, 224)
    renderer = Renderer(scene, cam.K, cam.width, cam.height)
    renderer.render(cam.positions[0], cam.rotations[0])  # builds the embree scene
    _STATE.update(cam=cam, renderer=renderer)


def _render_chunk(bounds: tuple[int, int]) -> int:
    cam, renderer = _STATE["cam"], _STATE["renderer"]
    for i in range(*bounds):
        renderer.render(cam.positions[i], cam.rotations[i])
    return bounds[1] - bounds[0]


def _median(values: list[float]) -> float:
    return float(np.median(values))


def bench_render(frames: int, workers: int, repeats: int) -> dict:
    """Frames per second of rendering only (scene loading and trajectory excluded)."""
    _init_renderer(frames)
    single, per_cpu = [], []
    for _ in range(repeats):
        start, cpu = time.perf_counter(), time.process_time()
        _render_chunk((0, frames))
        single.append(frames / (time.perf_counter() - start))
        per_cpu.append(frames / (time.process_time() - cpu))
    bounds = np.linspace(0, frames, workers + 1).astype(int)
    context = multiprocessing.get_context("spawn")
    parallel = []
    with ProcessPoolExecutor(
        workers, mp_context=context, initializer=_init_renderer, initargs=(frames,)
    ) as pool:
        list(pool.map(_render_chunk, [(0, 1)] * workers))  # wait until every worker is initialised
        for _ in range(repeats):
            start = time.perf_counter()
            done = sum(pool.map(_render_chunk, list(zip(bounds[:-1], bounds[1:]))))
            parallel.append(done / (time.perf_counter() - start))
    return {
        "frames": frames,
        "repeats": repeats,
        "fps_1_process": _median(single),
        "frames_per_cpu_second_1_process": _median(per_cpu),
        f"fps_{workers}_processes": _median(parallel),
    }


def synthetic_smpl_npz(path: Path, num_vertices: int = 6890) -> Path:
    """An SMPL-format model of SMPL's size: 4 vertices around each joint (regressed to it) and the rest
    on capsule surfaces along the bones (radii of the capsule body), skinned to the bone's parent joint."""
    from skeleton_mamba.skeletons import SMPL24
    from skeleton_mamba.tasks.egodance.builder.penetration import BONE_RADII
    from skeleton_mamba.tasks.motion.body.smpl import SMPL_REST_OFFSETS

    rng = np.random.default_rng(0)
    joints = np.zeros((24, 3))
    for j in range(1, 24):
        joints[j] = joints[SMPL24.parents[j]] + SMPL_REST_OFFSETS[j]
    tetra = 0.02 * np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])
    vertices, owner = [(joints[:, None] + tetra).reshape(-1, 3)], [np.repeat(np.arange(24), 4)]
    bones = SMPL24.bones()
    per_bone = np.full(len(bones), (num_vertices - 96) // len(bones))
    per_bone[: (num_vertices - 96) % len(bones)] += 1
    for (parent, child), n in zip(bones, per_bone):
        a, b = joints[parent], joints[child]
        axis = (b - a) / np.linalg.norm(b - a)
        e1 = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(axis, e1)
        s, angle = rng.random(n)[:, None], rng.uniform(0, 2 * np.pi, n)[:, None]
        ring = np.cos(angle) * e1 + np.sin(angle) * e2
        vertices.append(a + s * (b - a) + BONE_RADII[child] * ring)
        owner.append(np.full(n, parent))
    v = np.concatenate(vertices)
    owner = np.concatenate(owner)
    weights = np.zeros((len(v), 24))
    weights[np.arange(len(v)), owner] = 1.0
    regressor = np.zeros((24, len(v)))
    regressor[np.repeat(np.arange(24), 4), np.arange(96)] = 0.25
    faces = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
    np.savez(
        path,
        v_template=v,
        shapedirs=np.zeros((len(v), 3, 1)),
        posedirs=np.zeros((len(v), 3, 207)),
        J_regressor=regressor,
        weights=weights,
        kintree_table=np.stack([np.array(SMPL24.parents), np.arange(24)]),
        f=(faces[None] + 4 * np.arange(24)[:, None, None]).reshape(-1, 3),
    )
    return path


def bench_build(seconds: float, workers: int, smpl_model: str | None = None) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        motion = save_motion(
            Path(tmp) / "synthetic_bounce_120bpm_s0.npz", synthesize_dance(120, seconds, 60, "bounce")
        )
        cfg = BuildConfig(
            out=str(Path(tmp) / "ego"),
            scenes="procedural",
            num_rooms=2,
            workers=workers,
            progress=False,
            smpl_model=smpl_model,
        )
        start = time.perf_counter()
        summary = run_build(cfg, motion)
        elapsed = time.perf_counter() - start
    windows = summary.placed + summary.skipped
    return {
        "body": "capsules" if smpl_model is None else f"smpl mesh ({Path(smpl_model).name})",
        "motion_seconds": seconds,
        "windows": windows,
        "placed": summary.placed,
        "rejected_placements": summary.rejected,
        "build_seconds": elapsed,
        "build_seconds_per_motion_minute": elapsed / (windows * cfg.window_s / 60.0),
    }


def peak_rss_make_ego(caster: str, args: list[str], timeout_s: float) -> dict:
    """Runs ``sm make-ego ARGS --workers 1`` with one ray caster: its peak RSS (MB) and wall time.

    The peak is the kernel's ``ru_maxrss`` of that child (``os.wait4``), so every measurement is its own
    process and later ones do not inherit earlier peaks.
    """
    env = dict(os.environ, SKELETON_MAMBA_RAY_CASTER=caster)
    with tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "skeleton_mamba.tasks", "make-ego", *args, "--workers", "1"],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=err,
        )
        timer = threading.Timer(timeout_s, proc.kill)
        timer.start()
        _, status, usage = os.wait4(proc.pid, 0)
        timer.cancel()
        proc.returncode = os.waitstatus_to_exitcode(status)
        elapsed = time.perf_counter() - start
        err.seek(0)
        tail = err.read().decode(errors="replace")[-400:]
    result = {
        "caster": caster,
        "exit_code": proc.returncode,
        "seconds": elapsed,
        "peak_rss_mb": usage.ru_maxrss / 1024,  # KiB on Linux
    }
    if proc.returncode != 0:
        result["error"] = "killed after the time limit" if proc.returncode == -9 else tail
    return result


def bench_make_ego_memory(scene: str, window_s: float, timeout_s: float) -> list[dict]:
    """Peak RSS of ``sm make-ego`` with embree and with trimesh's caster, on the demo's data at 64 x 64
    and on the real scene mesh ``scene`` at 256 x 256 (one motion of ``window_s`` seconds each)."""
    from skeleton_mamba.tasks.egodance.builder.ray_caster import HAS_EMBREE
    from skeleton_mamba.tasks.motion.synthetic import make_demo_set

    cases = []
    with tempfile.TemporaryDirectory() as tmp:
        make_demo_set(Path(tmp) / "motions", count=1, duration_s=window_s)
        common = ["--motion", str(Path(tmp) / "motions"), "--window", str(window_s)]
        setups = [
            ("demo data, procedural rooms, 64 x 64", ["--scenes", "procedural", "--num-rooms", "2"], 64)
        ]
        if Path(scene).is_file():
            setups.append((f"{Path(scene).name}, 256 x 256", ["--scenes", scene, "--up-axis", "z"], 256))
        for label, scene_args, size in setups:
            for caster in ("embree", "trimesh") if HAS_EMBREE else ("trimesh",):
                out = Path(tmp) / f"ego_{caster}_{size}"
                size_args = ["--width", str(size), "--height", str(size)]
                run = peak_rss_make_ego(
                    caster, [*common, *scene_args, *size_args, "--out", str(out)], timeout_s
                )
                cases.append({"case": label, "window_s": window_s, **run})
    return cases


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--frames", type=int, default=120, help="frames rendered in the rendering benchmark")
    p.add_argument("--repeats", type=int, default=3, help="rendering runs (the median is reported)")
    p.add_argument("--motion-seconds", type=float, default=20.0, help="length of the end-to-end motion")
    p.add_argument("--smpl-model", default=None, help="SMPL model file (default: a synthetic SMPL-size one)")
    p.add_argument("--scene", default="../shared/data/scenes/simple_room.glb", help="real mesh (peak RSS)")
    p.add_argument("--rss-window", type=float, default=1.0, help="motion seconds built per peak-RSS run")
    p.add_argument("--rss-timeout", type=float, default=1800.0, help="time limit of one peak-RSS run (s)")
    p.add_argument("--only-memory", action="store_true", help="run the peak-RSS measurement only")
    args = p.parse_args(argv)
    result = {"machine": machine_info(), "load_average": os.getloadavg()}
    if not args.only_memory:
        with tempfile.TemporaryDirectory() as tmp:
            model = args.smpl_model or str(synthetic_smpl_npz(Path(tmp) / "synthetic_smpl_6890.npz"))
            result.update(
                resolution=[224, 224],
                render=bench_render(args.frames, args.workers, args.repeats),
                build=bench_build(args.motion_seconds, args.workers),
                build_smpl_mesh=bench_build(args.motion_seconds, args.workers, model),
            )
    result["make_ego_peak_rss"] = bench_make_ego_memory(args.scene, args.rss_window, args.rss_timeout)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"machine: {result['machine']}")
    if not args.only_memory:
        r = result["render"]
        print(
            f"render 224x224: {r['fps_1_process']:.1f} fps (1 process), "
            f"{r[f'fps_{args.workers}_processes']:.1f} fps ({args.workers} processes)"
        )
        for b in (result["build"], result["build_smpl_mesh"]):
            print(
                f"build ({b['body']}): {b['build_seconds']:.1f} s for {b['windows']} windows of 5 s "
                f"-> {b['build_seconds_per_motion_minute']:.1f} s per minute of motion"
            )
    for m in result["make_ego_peak_rss"]:
        print(
            f"sm make-ego peak RSS ({m['case']}, {m['caster']}): {m['peak_rss_mb']:.0f} MB, "
            f"{m['seconds']:.0f} s, exit {m['exit_code']}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
