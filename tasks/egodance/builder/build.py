"""The resumable, multi-process EgoAIST++ build ([EgoMusic] supp. Sec. 5).

For every motion file, the motion is resampled to ``fps`` and cut into ``window_s`` windows (5 s,
non-overlapping by default: "we divide the motion sequences into multiple 5-second subsequences"). Each
window gets a scene (scene files round-robin, or procedural rooms) and up to ``max_attempts`` random
placements (:mod:`.placement`); the first whose feet stay over the floor and whose first view sees the scene
on at least ``min_view_hits`` of its rays (:mod:`.placement_checks`), and whose penetration score ``S_p``
(:mod:`.penetration`) is at most ``threshold`` (2, [EgoMusic]'s value), is kept; the window is skipped with a
logged reason otherwise (the rejections are counted by reason in the summary).
The body scored is the capsule body, or the SMPL mesh when ``smpl_model`` names a model file
(:mod:`.body_mesh`; its lowest vertex then touches the floor, and the mesh score stops at the first
frames above the threshold, so the scores of rejected placements are lower bounds).
The kept window is rendered from the head camera (:mod:`.camera`, :mod:`.raycast`) and written in the
layout of :mod:`.layout`. Each window's random numbers come from ``(seed, crc32(sample_id))``, so a
build is reproducible whatever the worker count and order, and an interrupted build resumes: complete
samples and windows already skipped are not redone; temporary and unmarked folders are removed first,
and a complete sample whose files do not agree with its ``meta.json`` (a truncated ``rgb.mp4``, a short
``depth.npz``: :func:`.layout.sample_problem`) is rebuilt. A corrupt motion file stops the build with its
name, or with ``skip_bad`` is passed over and listed in the summary (``bad_inputs``).

The manual verification step of [EgoMusic] supp. Sec. 5 is left to the user (``meta.json`` keeps the score).
"""

from __future__ import annotations

import logging
import multiprocessing
import shutil
import zlib
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from skeleton_mamba.errors import DataFileError, InputError, worker_ignores_ctrl_c
from skeleton_mamba.io.bounded_read import read_json
from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.egodance.builder import layout
from skeleton_mamba.tasks.egodance.builder.body_mesh import get_body_model, pose_body
from skeleton_mamba.tasks.egodance.builder.camera import CameraTrajectory, head_camera, intrinsics
from skeleton_mamba.tasks.egodance.builder.config import BuildConfig
from skeleton_mamba.tasks.egodance.builder.penetration import mesh_penetration_score, penetration_score
from skeleton_mamba.tasks.egodance.builder.placement import place_points, random_placement
from skeleton_mamba.tasks.egodance.builder.placement_checks import (
    REJECTIONS,
    feet_off_floor,
    view_hit_share,
)
from skeleton_mamba.tasks.egodance.builder.procedural_scene import procedural_room
from skeleton_mamba.tasks.egodance.builder.raycast import render_trajectory
from skeleton_mamba.tasks.egodance.builder.scene import SceneMesh, load_scene
from skeleton_mamba.tasks.egodance.builder.scene_check import MAX_SCENE_FACES, check_scene_file
from skeleton_mamba.tasks.motion.body.kinematics import forward_kinematics
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from skeleton_mamba.tasks.motion.body.smpl import smpl_rest_offsets
from skeleton_mamba.tasks.motion.formats import aistpp
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, load_motion

__all__ = ["BuildConfig", "WindowTask", "plan_windows", "build_window", "run_build", "SCENE_SUFFIXES"]

log = logging.getLogger(__name__)
SCENE_SUFFIXES = (".glb", ".gltf", ".obj", ".ply", ".off", ".stl")
AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".opus", ".mp3")
# Settings that change the data: a resumed build must use the same values.
_FIXED_SETTINGS = (
    "fps",
    "window_s",
    "stride_s",
    "width",
    "height",
    "fov",
    "threshold",
    "seed",
    "frame_format",
    "up_axis",
    "scene_pattern",
    "scenes",
    "num_rooms",
    "camera_forward",
    "camera_up",
    "smpl_model",
)


@dataclass(frozen=True)
class WindowTask:
    """One window to build: ``window_index`` of the windows of ``motion_path``, rendered in ``scene_key``."""

    sample_id: str
    motion_path: str
    window_index: int
    start_frame: int
    num_frames: int
    scene_key: str


@dataclass
class BuildSummary:
    planned: int = 0
    complete: int = 0
    placed: int = 0
    rejected: int = 0
    skipped: int = 0
    already_complete: int = 0
    already_skipped: int = 0
    rebuilt: int = 0  # complete samples whose files failed layout.sample_problem on resume
    skip_reasons: list[str] = field(default_factory=list)
    rejections: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REJECTIONS, 0))  # by reason
    bad_inputs: list[str] = field(default_factory=list)  # corrupt motion files passed over (--skip-bad)


# ---------------------------------------------------------------- inputs
def motion_files(motion: str | Path, keep_ignored: bool = False) -> list[Path]:
    """Our ``.npz`` motions and AIST++ ``.pkl`` motions of a file or folder (AIST++ ignore list dropped)."""
    path = Path(motion)
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise FileNotFoundError(f"motion path not found: {path}")
    files = sorted(p for p in path.iterdir() if p.suffix in (".npz", ".pkl"))
    if not keep_ignored:
        ignored = aistpp.ignore_list()
        files = [p for p in files if p.stem not in ignored]
    if not files:
        raise FileNotFoundError(f"{path}: no .npz or .pkl motion files")
    return files


def read_motion(path: str | Path) -> MotionData:
    """An SMPL motion from our ``.npz`` format or an AIST++ ``.pkl`` (restricted unpickler)."""
    path = Path(path)
    motion = aistpp.load_aistpp_motion(path) if path.suffix == ".pkl" else load_motion(path)
    if motion.poses is None:
        raise ValueError(
            f"{path}: the builder needs SMPL parameters (smpl_poses, smpl_trans), not joints only"
        )
    return motion


def scene_keys(cfg: BuildConfig) -> list[str]:
    """``procedural:<seed>`` keys or scene file paths."""
    if cfg.scenes == "procedural":
        return [f"procedural:{cfg.seed * 1000 + k}" for k in range(cfg.num_rooms)]
    path = Path(cfg.scenes)
    if path.is_file():
        return [str(path)]
    if not path.is_dir():
        raise FileNotFoundError(f"scenes: {path} is neither 'procedural', a scene file nor a folder")
    if cfg.scene_pattern:
        files = sorted(str(p) for p in path.glob(cfg.scene_pattern) if p.is_file())
    else:
        files = sorted(str(p) for p in path.rglob("*") if p.suffix.lower() in SCENE_SUFFIXES)
    if not files:
        wanted = cfg.scene_pattern or ", ".join(SCENE_SUFFIXES)
        raise FileNotFoundError(f"{path}: no scene meshes ({wanted})")
    return files


def plan_windows(
    cfg: BuildConfig, motions: list[Path], bad_inputs: list[str] | None = None
) -> list[WindowTask]:
    """All windows of all motions, in a fixed order, each with its scene.

    A motion file that cannot be read stops the plan with its name, unless ``cfg.skip_bad``: then its
    error message is appended to ``bad_inputs`` and the other files are planned.
    """
    keys = scene_keys(cfg)
    window = round(cfg.window_s * cfg.fps)
    stride = round(cfg.stride * cfg.fps)
    tasks: list[WindowTask] = []
    for path in motions:
        try:
            motion = read_motion(path)
        except (ValueError, OSError, EOFError) as e:  # DataFileError, UnsafePickleError, unreadable files
            message = str(e) if str(path) in str(e) else f"{path}: {e}"
            if not cfg.skip_bad:
                raise DataFileError(f"{message} (--skip-bad goes on past corrupt motion files)") from e
            log.warning("skipping corrupt motion file: %s", message)
            if bad_inputs is not None:
                bad_inputs.append(message)
            continue
        frames = int(np.floor((motion.num_frames - 1) * cfg.fps / motion.fps + 1e-9)) + 1
        for w, start in enumerate(aistpp.window_starts(frames, window, stride)):
            sample_id = f"{path.stem}__w{w:03d}"
            tasks.append(WindowTask(sample_id, str(path), w, start, window, keys[len(tasks) % len(keys)]))
    return tasks


def music_reference(motion_path: Path, start_s: float, end_s: float, music_dir: str | None) -> dict:
    """The music slice that plays during a window (``meta.json`` ``music``)."""
    for suffix in AUDIO_SUFFIXES:  # an audio file with the motion's stem (the synthetic generators write one)
        sidecar = motion_path.with_suffix(suffix)
        if sidecar.is_file():
            return {"id": sidecar.stem, "path": str(sidecar), "start_s": start_s, "end_s": end_s}
    try:
        music = aistpp.music_id(motion_path.stem)
    except ValueError:
        return {"id": None, "path": None, "start_s": start_s, "end_s": end_s}
    path = None
    if music_dir is not None:
        candidates = [Path(music_dir) / f"{music}{s}" for s in AUDIO_SUFFIXES]
        path = next((str(c) for c in candidates if c.is_file()), None)
    return {"id": music, "path": path, "start_s": start_s, "end_s": end_s}


# ---------------------------------------------------------------- per-worker caches
_SCENES: dict[tuple[str, str], SceneMesh] = {}
_WINDOWS: dict[tuple, list[MotionData]] = {}


def get_scene(key: str, up_axis: str, max_faces: int = MAX_SCENE_FACES) -> SceneMesh:
    if (key, up_axis) not in _SCENES:
        if key.startswith("procedural:"):
            _SCENES[key, up_axis] = procedural_room(int(key.split(":", 1)[1]))
        else:
            scene = load_scene(key, up_axis, max_faces)
            if scene.name == "mesh":  # Replica: <scene>/mesh.ply -> name the scene after its folder
                scene.name = Path(key).parent.name
            _SCENES[key, up_axis] = scene
    return _SCENES[key, up_axis]


def _windows(path: str, fps: float, window_s: float, stride_s: float) -> list[MotionData]:
    key = (path, fps, window_s, stride_s)
    if key not in _WINDOWS:
        _WINDOWS.clear()  # one motion at a time per worker (tasks come motion by motion)
        _WINDOWS[key] = aistpp.motion_windows(read_motion(path), fps, window_s, stride_s)
    return _WINDOWS[key]


def _pool_context() -> multiprocessing.context.BaseContext:
    """Worker start method: never fork the (possibly multi-threaded) caller.

    A forked child inherits embree/TBB and OpenMP thread-pool state and can hang. ``forkserver`` forks
    the workers from a clean server that imports this module once; ``spawn`` where it is unavailable.
    """
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload([__name__])
        return context
    return multiprocessing.get_context("spawn")


def _init_worker() -> None:
    """One torch thread per worker process; Ctrl-C is the parent's to handle (it stops the workers)."""
    worker_ignores_ctrl_c()
    torch.set_num_threads(1)


def _stop_pool(pool: ProcessPoolExecutor, others: set[multiprocessing.process.BaseProcess]) -> None:
    """Cancel the queued windows and end the workers now (a window in progress leaves only a temp folder).

    The executor has no public handle on its workers (until Python 3.14's ``terminate_workers``): they are
    this process's children that ``multiprocessing.active_children()`` lists now and did not list when the
    pool was made (``others``).
    """
    workers = [process for process in multiprocessing.active_children() if process not in others]
    pool.shutdown(wait=False, cancel_futures=True)
    for process in workers:
        process.terminate()
    for process in workers:
        process.join(timeout=5)


# ---------------------------------------------------------------- one window
def build_window(task: WindowTask, cfg: BuildConfig) -> dict:
    """Place, score, render and write one window; returns ``{"status", "sample_id", "rejected", ...}``."""
    win = _windows(task.motion_path, cfg.fps, cfg.window_s, cfg.stride)[task.window_index]
    poses = torch.from_numpy(np.asarray(win.poses, dtype=np.float64))
    root = torch.from_numpy(np.asarray(win.root_position(), dtype=np.float64))
    local = axis_angle_to_matrix(poses)  # (T, 24, 3, 3)
    joints_t, world_t = forward_kinematics(local, root, smpl_rest_offsets(torch.float64), SMPL24.parents)
    joints, world = joints_t.numpy(), world_t.numpy()
    scene = get_scene(task.scene_key, cfg.up_axis, cfg.max_faces)
    rng = np.random.default_rng([cfg.seed, zlib.crc32(task.sample_id.encode())])
    body = pose_body(get_body_model(cfg.smpl_model), poses, root) if cfg.smpl_model else None
    scores: list[float] = []
    rejections = dict.fromkeys(REJECTIONS, 0)
    placement = None
    K = intrinsics(cfg.width, cfg.height, cfg.fov)

    def first_view(candidate) -> CameraTrajectory:  # the head camera of the window's first frame
        head = place_points(joints[:1, 15], candidate), candidate.rotation @ world[:1, 15]
        return head_camera(*head, K, cfg.width, cfg.height, cfg.camera_forward, cfg.camera_up)

    for _ in range(cfg.max_attempts):
        if body is None:
            candidate = random_placement(joints, scene, rng)
        else:
            candidate = random_placement(joints, scene, rng, 0.0, float(body.vertices[..., 1].min()))
        placed = place_points(joints, candidate)
        if body is None:
            score = penetration_score(scene, placed, cfg.penetration_stride)
        else:
            score = mesh_penetration_score(
                scene,
                place_points(body.vertices, candidate),
                place_points(body.joints, candidate),
                body.anchor,
                cfg.penetration_stride,
                stop_above=cfg.threshold,
            )
        scores.append(score)
        if score > cfg.threshold:
            rejections["penetration"] += 1
        elif feet_off_floor(scene, placed, cfg.penetration_stride):  # a foot beyond the floor's edge
            rejections["feet"] += 1
        elif (
            view_hit_share(scene, first_view(candidate)) < cfg.min_view_hits
        ):  # the eyes see (almost) nothing
            rejections["view"] += 1
        else:
            placement = candidate
            break
    if placement is None:
        best = f" (best S_p {min(scores):.2f} cm)" if scores else ""
        counts = ", ".join(f"{n} {why}" for why, n in rejections.items())
        reason = (
            f"no placement with S_p <= {cfg.threshold}, feet over the floor and at least "
            f"{cfg.min_view_hits:.0%} of the first view on geometry in {cfg.max_attempts} attempts "
            f"(rejected: {counts}){best} in scene {scene.name}"
        )
        skipped = Path(cfg.out) / layout.SKIPPED
        skipped.mkdir(parents=True, exist_ok=True)
        layout.write_json(
            skipped / f"{task.sample_id}.json",
            {"sample_id": task.sample_id, "reason": reason, "scores": scores, "scene": scene.name,
             "rejections": rejections},
        )  # fmt: skip
        return {"status": "skipped", "sample_id": task.sample_id, "rejected": cfg.max_attempts,
                "rejections": rejections, "reason": reason}  # fmt: skip

    rot = placement.rotation
    placed = place_points(joints, placement)
    camera = head_camera(
        placed[:, 15], rot @ world[:, 15], K, cfg.width, cfg.height, cfg.camera_forward, cfg.camera_up
    )
    rgb, depth = render_trajectory(scene, camera)

    placed_poses = poses.clone()
    placed_poses[:, 0] = matrix_to_axis_angle(torch.from_numpy(rot) @ local[:, 0])
    motion = MotionData(
        fps=cfg.fps,
        skeleton="smpl24",
        poses=placed_poses.numpy(),
        trans=place_points(root.numpy(), placement),
        scaling=1.0,
        joints=placed,
    )
    start_s, end_s = task.start_frame / cfg.fps, (task.start_frame + task.num_frames) / cfg.fps
    motion_path = Path(task.motion_path)
    meta = {
        "sample_id": task.sample_id,
        "synthetic": motion_path.stem.startswith("synthetic"),
        "motion": {
            "source": str(motion_path),
            "window_index": task.window_index,
            "start_frame": task.start_frame,
            "num_frames": task.num_frames,
            "start_s": start_s,
            "end_s": end_s,
        },
        "music": music_reference(motion_path, start_s, end_s, cfg.music_dir),
        "scene": {
            "name": scene.name,
            "source": scene.source,
            "up_axis": cfg.up_axis,
            "floor_height": scene.floor_height,
        },
        "placement": placement.to_dict(),
        "body": {"model": "capsules"} if body is None else {"model": "smpl", "file": cfg.smpl_model},
        "penetration_score": scores[-1],
        "threshold": cfg.threshold,
        "attempts": len(scores),
        "frames": {
            "format": cfg.frame_format,
            "count": len(rgb),
            "width": cfg.width,
            "height": cfg.height,
            "fps": cfg.fps,
        },
    }
    cam = {
        "positions": camera.positions,
        "rotations": camera.rotations,
        "K": K,
        "width": cfg.width,
        "height": cfg.height,
        "fps": cfg.fps,
    }
    layout.write_sample(cfg.out, layout.EgoSample(meta, motion, cam, rgb, depth), cfg.frame_format)
    return {"status": "placed", "sample_id": task.sample_id, "rejected": sum(rejections.values()),
            "rejections": rejections, "score": scores[-1]}  # fmt: skip


# ---------------------------------------------------------------- the whole build
def _check_settings(cfg: BuildConfig) -> None:
    """Write ``build.json``, or check that a resumed build uses the same data settings."""
    path = Path(cfg.out) / "build.json"
    settings = {k: getattr(cfg, k) for k in _FIXED_SETTINGS}
    if path.is_file():
        old = read_json(path, error=DataFileError)
        diff = {k: (old.get(k), v) for k, v in settings.items() if old.get(k) != v}
        if diff:
            raise InputError(f"{cfg.out} was built with other settings {diff} (old, new): use another --out")
    else:
        layout.write_json(path, settings)


def run_build(cfg: BuildConfig, motion: str | Path, created: bool | None = None) -> BuildSummary:
    """Build (or resume) a dataset; returns the counts also written to ``summary.json``.

    Every scene file's declared size is checked before anything is written or loaded; a build that stops
    before it wrote a sample removes the output folder it created (a bad scene found when it is loaded;
    ``created``: whether the caller created ``cfg.out`` for this build, by default whether it is missing).
    """
    out = Path(cfg.out)
    for key in scene_keys(cfg):
        if not key.startswith("procedural:"):
            check_scene_file(key, cfg.max_faces)
    layout.check_real_folders(out)
    created = not out.exists() if created is None else created
    try:
        return _run_build(cfg, motion, out)
    except BaseException:
        if (
            created
            and out.is_dir()
            and not layout.complete_samples(out)
            and not (out / layout.SKIPPED).exists()
        ):
            shutil.rmtree(out, ignore_errors=True)
        raise


def _run_build(cfg: BuildConfig, motion: str | Path, out: Path) -> BuildSummary:
    if cfg.smpl_model is not None:  # fail early on a bad model file, and record it by absolute path
        cfg.smpl_model = str(Path(cfg.smpl_model).resolve())
        get_body_model(cfg.smpl_model)
    out.mkdir(parents=True, exist_ok=True)
    _check_settings(cfg)
    removed = layout.clean_incomplete(out)
    if removed:
        log.info("removed %d incomplete sample folder(s): %s", len(removed), ", ".join(removed))
    bad_inputs: list[str] = []
    tasks = plan_windows(cfg, motion_files(motion, cfg.keep_ignored), bad_inputs)
    summary = BuildSummary(planned=len(tasks), bad_inputs=bad_inputs)
    todo = []
    for task in tasks:
        folder = layout.sample_dir(out, task.sample_id)
        problem = layout.sample_problem(folder) if layout.is_complete(folder) else None
        if problem is not None and layout.remove_sample_folder(folder):
            log.warning("rebuilding %s: %s", task.sample_id, problem)
            summary.rebuilt += 1
        elif problem is not None:
            raise DataFileError(
                f"{folder}: {problem}, and it holds files a build does not write; move it out of the build"
            )
        if layout.is_complete(folder):
            summary.already_complete += 1
        elif (out / layout.SKIPPED / f"{task.sample_id}.json").is_file():
            summary.already_skipped += 1
        else:
            todo.append(task)
    counts: Counter = Counter()

    def record(result: dict) -> None:
        counts[result["status"]] += 1
        counts["rejected"] += result["rejected"]
        for why, n in result.get("rejections", {}).items():
            summary.rejections[why] = summary.rejections.get(why, 0) + n
        if result["status"] == "skipped":
            log.warning("skipped %s: %s", result["sample_id"], result["reason"])
            summary.skip_reasons.append(f"{result['sample_id']}: {result['reason']}")

    bar = tqdm(total=len(todo), desc="make-ego", unit="window", disable=not cfg.progress)
    if cfg.workers <= 1 or len(todo) <= 1:
        for task in todo:
            record(build_window(task, cfg))
            bar.update()
    else:
        others = set(multiprocessing.active_children())
        pool = ProcessPoolExecutor(
            max_workers=min(cfg.workers, len(todo)), mp_context=_pool_context(), initializer=_init_worker
        )
        try:
            futures = [pool.submit(build_window, task, cfg) for task in todo]
            for future in as_completed(futures):
                record(future.result())
                bar.update()
        except BaseException:
            _stop_pool(pool, others)  # Ctrl-C or a failed window: do not wait for the queued windows
            raise
        pool.shutdown()
    bar.close()
    summary.placed, summary.skipped, summary.rejected = (
        counts["placed"],
        counts["skipped"],
        counts["rejected"],
    )
    summary.complete = len(layout.complete_samples(out))
    layout.write_json(out / "summary.json", asdict(summary))
    return summary
