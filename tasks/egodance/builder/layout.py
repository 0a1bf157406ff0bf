"""The on-disk layout of an EgoAIST++-style dataset built by ``sm make-ego`` (read and write).

::

    <out>/
      build.json                 the build settings (fps, window, resolution, fov, seed, threshold, ...);
                                 a resumed build must use the same settings
      summary.json               counts of the last run: planned windows, complete samples, and, in
                                 that run, placed windows, rejected placements, skipped windows
      skipped/<sample_id>.json   a window given up after ``max_attempts`` placements: reason, scores
                                 (a resumed build does not retry it; delete the file to retry)
      samples/<sample_id>/       ONE COMPLETE SAMPLE (the folder exists only once the sample is complete)
        meta.json                see below
        motion.npz               the placed motion window, our motion format
                                 (:mod:`skeleton_mamba.tasks.motion.formats.motion_file`): smpl_poses (T, 72),
                                 smpl_trans (T, 3) metres with smpl_scaling 1, fps, skeleton "smpl24",
                                 joints (T, 24, 3); y-up SCENE coordinates (the placement applied)
        camera.npz               positions (T, 3) float32 optical centres; rotations (T, 3, 3) float32
                                 camera-to-world, OpenCV axes (x right, y down, z forward); K (3, 3)
                                 intrinsics; width, height, fps (see ``builder/camera.py``)
        rgb.mp4 | rgb/%06d.png   the egocentric RGB frames (H, W, 3), T frames at ``fps``
        depth.npz                depth (T, H, W) uint16 z-depth in millimetres, 0 = nothing hit
        COMPLETE                 completion marker (written last)
      samples/.tmp-<sample_id>-<pid>/   a sample being written (never read; removed on resume)

``meta.json`` keys: ``sample_id``; ``synthetic`` (true when the motion came from the procedural
generators); ``motion`` {``source`` path, ``window_index``, ``start_frame``, ``num_frames`` (at the build
fps), ``start_s``, ``end_s``}; ``music`` {``id`` (AIST++ music id, or the audio file stem), ``path`` (or
null when unknown), ``start_s``, ``end_s``}: the slice of the track that plays during the window;
``scene`` {``name``, ``source``, ``up_axis`` of the file, ``floor_height`` (y-up scene frame)};
``placement`` {``yaw`` radians about +y, ``translation`` (3,) metres: ``p_scene = R_y(yaw) p + t``};
``body`` {``model``: "capsules", or "smpl" with ``file`` the SMPL model file}: the body ``S_p`` was
computed for; ``penetration_score`` (``S_p`` in cm, ``builder/penetration.py``), ``threshold``, ``attempts``;
``frames`` {``format`` "mp4" or "png", ``count``, ``width``, ``height``, ``fps``}.

Paths in ``meta.json`` (:data:`META_PATHS`: the motion source, the music, the scene, the SMPL model file) are
written twice: as found (absolute for the demo's data), and relative to the sample's folder under the key
with ``_relative`` appended (``music.path_relative``), so a built set (with the files it points to) can be
moved or copied as a whole. :func:`read_meta` gives each path from its relative form when that file is
there, else as written (the samples of earlier builds, which have no relative form).

Atomicity: a sample is written into ``samples/.tmp-<id>-<pid>/``, the ``COMPLETE`` marker is written
last, then the folder is renamed to ``samples/<id>`` (``os.replace``, atomic on one file system). A
reader lists only folders holding ``COMPLETE`` (:func:`complete_samples`), so an interrupted build never
yields a half-written sample; :func:`clean_incomplete` removes the temporary folders an interrupted
build left before it resumes (so run one build per output folder at a time). A build removes only folders
holding nothing but a sample's files, never follows a symbolic link, and refuses a ``samples/`` or
``skipped/`` that is a link (:func:`check_real_folders`).
"""

from __future__ import annotations

import json
import os
import shutil
import zipfile
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np

from skeleton_mamba.errors import DataFileError, InputError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.io.bounded_read import read_json
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, load_motion, save_motion
from skeleton_mamba.tasks.motion.formats.mp4 import write_mp4
from skeleton_mamba.tasks.motion.io.value_checks import NPY_HEADER_ERRORS, load_npz, read_npy_header

__all__ = [
    "COMPLETE",
    "META_PATHS",
    "read_meta",
    "relative_meta",
    "SAMPLES",
    "EgoSample",
    "sample_dir",
    "is_complete",
    "sample_problem",
    "complete_samples",
    "clean_incomplete",
    "write_sample",
    "read_sample",
    "read_frames",
    "write_json",
]

COMPLETE = "COMPLETE"
SAMPLES = "samples"
SKIPPED = "skipped"
TMP_PREFIX = ".tmp-"


@dataclass
class EgoSample:
    """Everything one sample folder holds (arrays at the build fps, T frames).

    Attributes:
        meta: the ``meta.json`` dictionary (module docstring).
        motion: the placed motion window (scene coordinates).
        camera: ``positions`` (T, 3), ``rotations`` (T, 3, 3), ``K`` (3, 3), ``width``, ``height``, ``fps``.
        rgb: (T, H, W, 3) uint8, or None when not loaded.
        depth: (T, H, W) float32 metres, or None when not loaded.
    """

    meta: dict
    motion: MotionData
    camera: dict
    rgb: np.ndarray | None = None
    depth: np.ndarray | None = None


META_PATHS = (("motion", "source"), ("music", "path"), ("scene", "source"), ("body", "file"))


def relative_meta(meta: dict, folder: str | Path) -> dict:
    """``meta`` with ``<key>_relative`` beside each existing file of :data:`META_PATHS`: its path relative to
    ``folder`` (POSIX form). The input is not changed."""
    out = dict(meta)
    for section, key in META_PATHS:
        entry = out.get(section)
        value = entry.get(key) if isinstance(entry, dict) else None
        if isinstance(value, str) and Path(value).exists():  # not "procedural", nor a missing file
            relative = Path(os.path.relpath(Path(value).resolve(), Path(folder).resolve())).as_posix()
            out[section] = {**entry, f"{key}_relative": relative}
    return out


def read_meta(folder: str | Path) -> dict:
    """A sample's ``meta.json`` with each path of :data:`META_PATHS` taken from its relative form (resolved
    against the sample folder) when that file exists, else as written (module docstring)."""
    folder = Path(folder)
    meta = read_json(folder / "meta.json", error=DataFileError)  # the bounded reader
    if not isinstance(meta, dict):
        raise DataFileError(f"{folder / 'meta.json'}: expected a JSON object")
    for section, key in META_PATHS:
        entry = meta.get(section)
        relative = entry.get(f"{key}_relative") if isinstance(entry, dict) else None
        if isinstance(relative, str) and not Path(relative).is_absolute() and (folder / relative).exists():
            meta[section] = {**entry, key: os.path.normpath(folder / relative)}
    return meta


def write_json(path: Path, data: dict) -> None:
    """Write JSON through a temporary file and an atomic rename."""
    with atomic_open(path, "w", encoding="utf-8") as f:
        f.write(json.dumps(data, indent=2, sort_keys=True))


def sample_dir(root: str | Path, sample_id: str) -> Path:
    return Path(root) / SAMPLES / sample_id


def is_complete(folder: Path) -> bool:
    return (folder / COMPLETE).is_file()


def complete_samples(root: str | Path) -> list[Path]:
    """The complete sample folders of a dataset, sorted by id."""
    base = Path(root) / SAMPLES
    if not base.is_dir():
        return []
    return sorted(p for p in base.iterdir() if p.is_dir() and not p.name.startswith(".") and is_complete(p))


SAMPLE_FILES = frozenset({"meta.json", "motion.npz", "camera.npz", "depth.npz", "rgb.mp4", "rgb", COMPLETE})
"""The names a sample folder may hold (module docstring); ``rgb/`` holds ``%06d.png`` frames only."""


def check_real_folders(root: str | Path) -> None:
    """Refuse a build folder whose ``samples/`` or ``skipped/`` is a symbolic link or a file: a build
    writes, and cleans up, inside real folders of its own only.

    Raises:
        InputError: naming the entry.
    """
    for name in (SAMPLES, SKIPPED):
        path = Path(root) / name
        if path.is_symlink() or (path.exists() and not path.is_dir()):
            what = "a symbolic link" if path.is_symlink() else "not a folder"
            raise InputError(f"{path}: is {what}; a build writes into real folders of its own only")


def _is_sample_folder(path: Path) -> bool:
    """Whether ``path`` is a real folder holding only what :func:`write_sample` writes (so removing it
    removes nothing else)."""
    if path.is_symlink() or not path.is_dir():
        return False
    entries = list(path.iterdir())
    if any(e.name not in SAMPLE_FILES or e.is_symlink() for e in entries):
        return False
    rgb = path / "rgb"
    return not rgb.exists() or (
        rgb.is_dir() and all(f.suffix == ".png" and f.is_file() and not f.is_symlink() for f in rgb.iterdir())
    )


def remove_sample_folder(path: Path) -> bool:
    """Remove ``path`` when it is a sample folder a build wrote (:func:`_is_sample_folder`); returns whether
    it was removed."""
    if not _is_sample_folder(path):
        return False
    shutil.rmtree(path)
    return True


def clean_incomplete(root: str | Path) -> list[str]:
    """Remove the temporary sample folders an interrupted build left (``samples/.tmp-*`` holding only a
    sample's files); returns their names. Nothing else is removed: any other folder without a completion
    marker is not a build's (a build renames a complete folder into place) and is left as it is."""
    base = Path(root) / SAMPLES
    check_real_folders(root)
    removed: list[str] = []
    if base.is_dir():
        for p in sorted(base.iterdir()):
            if p.name.startswith(TMP_PREFIX) and remove_sample_folder(p):
                removed.append(p.name)
    return removed


def _npz_shapes(path: Path) -> dict[str, tuple[int, ...]]:
    """The array shapes of an ``.npz`` from the member headers (nothing is decompressed beyond them)."""
    shapes = {}
    with zipfile.ZipFile(path) as archive:
        for name in archive.namelist():
            with archive.open(name) as member:
                shapes[name.removesuffix(".npy")] = read_npy_header(member)[0]
    return shapes


def _count_video_frames(path: Path) -> int:

    return imageio_ffmpeg.count_frames_and_secs(str(path))[0]


def sample_problem(folder: str | Path) -> str | None:
    """Why a COMPLETE sample folder cannot be trusted, or ``None`` when its files agree with ``meta.json``.

    Checks that every file of the layout is present and not empty and that ``motion.npz``, ``camera.npz``,
    ``depth.npz`` (array headers) and the RGB frames (``rgb.mp4``: counted by an ffmpeg stream copy, no
    decoding; ``rgb/``: the PNG count) all hold ``meta["frames"]["count"]`` frames (depth: of ``height`` x
    ``width``). A build interrupted while copying, or a file truncated afterwards, fails these checks; a
    resumed build rebuilds the sample.
    """
    folder = Path(folder)
    try:
        meta = read_json(folder / "meta.json", error=DataFileError)
        frames = meta["frames"]
        count, fmt = int(frames["count"]), frames["format"]
        size = (int(frames["height"]), int(frames["width"]))
        rgb = folder / ("rgb.mp4" if fmt == "mp4" else "rgb")
        for name in ("motion.npz", "camera.npz", "depth.npz", *(("rgb.mp4",) if fmt == "mp4" else ())):
            if not (folder / name).is_file() or (folder / name).stat().st_size == 0:
                return f"{name} is missing or empty"
        lengths = {
            "motion.npz": _npz_shapes(folder / "motion.npz").get("smpl_poses", (None,))[0],
            "camera.npz": _npz_shapes(folder / "camera.npz").get("positions", (None,))[0],
        }
        depth = _npz_shapes(folder / "depth.npz").get("depth")
        if depth is None or depth[1:] != size:
            return f"depth.npz holds {depth}, expected ({count}, {size[0]}, {size[1]})"
        lengths["depth.npz"] = depth[0]
        if fmt == "mp4":
            lengths["rgb.mp4"] = _count_video_frames(rgb)
        else:
            pngs = sorted(rgb.glob("*.png"))
            if any(p.stat().st_size == 0 for p in pngs):
                return "an rgb/*.png frame is empty"
            lengths["rgb/"] = len(pngs)
    except (*NPY_HEADER_ERRORS, KeyError, TypeError, RuntimeError, zipfile.BadZipFile) as e:
        return f"unreadable ({type(e).__name__}: {e})"
    wrong = {name: n for name, n in lengths.items() if n != count}
    return f"frame counts {wrong} differ from meta.json's {count}" if wrong else None


def _write_frames(folder: Path, rgb: np.ndarray, fps: float, fmt: str) -> None:

    if fmt == "png":
        (folder / "rgb").mkdir()
        for i, frame in enumerate(rgb):
            iio.imwrite(folder / "rgb" / f"{i:06d}.png", frame)
    elif fmt == "mp4":
        # yuv420p needs even sizes: the encoder would otherwise resize; keep the exact size with yuv444p
        even = rgb.shape[1] % 2 == 0 and rgb.shape[2] % 2 == 0
        # quality 8 of imageio-ffmpeg (crf 10), preset veryfast (half the CPU of "medium" for ~6% larger
        # files at 224 x 224); ffmpeg's exit status, errors and video stream are checked
        pixels = "yuv420p" if even else "yuv444p"
        write_mp4(folder / "rgb.mp4", rgb, (rgb.shape[2], rgb.shape[1]), fps, crf=10, pix_fmt=pixels)
    else:
        raise ValueError(f"frame format must be 'png' or 'mp4', got {fmt!r}")


def write_sample(root: str | Path, sample: EgoSample, frame_format: str = "mp4") -> Path:
    """Write a complete sample atomically (module docstring) and return its final folder."""
    if sample.rgb is None or sample.depth is None:
        raise ValueError("write_sample needs rgb and depth frames")
    base = Path(root) / SAMPLES
    base.mkdir(parents=True, exist_ok=True)
    sample_id = sample.meta["sample_id"]
    tmp = base / f"{TMP_PREFIX}{sample_id}-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir()
    save_motion(tmp / "motion.npz", sample.motion)
    cam = sample.camera
    np.savez(
        tmp / "camera.npz",
        positions=np.asarray(cam["positions"], np.float32),
        rotations=np.asarray(cam["rotations"], np.float32),
        K=np.asarray(cam["K"], np.float64),
        width=np.asarray(cam["width"]),
        height=np.asarray(cam["height"]),
        fps=np.asarray(float(cam["fps"])),
    )
    _write_frames(tmp, sample.rgb, float(cam["fps"]), frame_format)
    depth_mm = np.clip(np.round(sample.depth * 1000.0), 0, np.iinfo(np.uint16).max).astype(np.uint16)
    np.savez_compressed(tmp / "depth.npz", depth=depth_mm)
    meta = relative_meta(sample.meta, base / sample_id)  # where the folder ends up
    (tmp / "meta.json").write_text(json.dumps(meta, indent=2, sort_keys=True), encoding="utf-8")
    (tmp / COMPLETE).write_text("ok\n", encoding="utf-8")
    final = base / sample_id
    if (final.exists() or final.is_symlink()) and not remove_sample_folder(final):  # a damaged sample's
        shutil.rmtree(tmp)
        raise InputError(f"{final}: holds files a build does not write; move it out of the build folder")
    os.replace(tmp, final)
    return final


def read_frames(folder: str | Path) -> np.ndarray:
    """The (T, H, W, 3) uint8 RGB frames of a sample folder (``rgb.mp4`` or ``rgb/*.png``)."""

    folder = Path(folder)
    if (folder / "rgb.mp4").is_file():
        return np.asarray(iio.imread(folder / "rgb.mp4"))
    pngs = sorted((folder / "rgb").glob("*.png"))
    if not pngs:
        raise FileNotFoundError(f"{folder}: no rgb.mp4 and no rgb/*.png frames")
    return np.stack([iio.imread(p) for p in pngs])


def read_sample(folder: str | Path, load_frames: bool = True) -> EgoSample:
    """Read one sample folder; raises when it is not complete or a file is missing."""
    folder = Path(folder)
    if not is_complete(folder):
        raise ValueError(f"{folder}: not a complete sample (no {COMPLETE} marker)")
    meta = read_meta(folder)
    camera = load_npz(folder / "camera.npz")
    for key in ("width", "height"):
        camera[key] = int(camera[key])
    camera["fps"] = float(camera["fps"])
    sample = EgoSample(meta=meta, motion=load_motion(folder / "motion.npz"), camera=camera)
    if load_frames:
        sample.rgb = read_frames(folder)
        sample.depth = load_npz(folder / "depth.npz")["depth"].astype(np.float32) / 1000.0
    return sample
