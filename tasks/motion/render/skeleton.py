"""Skeleton animation rendering to mp4 (with music) or GIF.

Each frame shows the bones and joints (left side blue, right side red, midline grey), their shadow on
a floor grid at the clip's lowest point, and the time. The camera looks at the body from a fixed direction
and follows the root's smoothed horizontal position at the height of the middle of the clip's vertical
extent. Its distance is fitted to the whole clip (:func:`fit_cameras`): the body's tallest pose fills
about 60 % of the frame's height, or less where a joint of any frame (a jump, raised arms, a quick step
the smoothed camera lags behind) would otherwise come closer than ``margin_fraction`` to an image edge.
Drawing is done directly with OpenCV (anti-aliased lines, painter's order by depth), frames are
encoded by the ffmpeg binary that imageio-ffmpeg ships (:mod:`skeleton_mamba.tasks.motion.formats.mp4`: exit
status, errors and streams checked), and music is muxed into the mp4 (AAC), cut to the motion's length. The
music is read by the one checked reader (:mod:`skeleton_mamba.tasks.motion.music.audio_io`) before anything is
written, so audio that is unreadable, out of bounds or holds no samples is refused and never leaves an mp4
without its sound. The file is written under a temporary name beside the target and renamed when complete.

Input joints are y-up (the toolkit's convention) in any unit: the floor grid spacing is chosen from
the body's size (1 m for a human in metres).
"""

from __future__ import annotations

import math
import os
import re
import tempfile
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import cv2
import numpy as np
import soundfile
from PIL import Image
from tqdm import tqdm

from skeleton_mamba.io.atomic import atomic_path, check_writable
from skeleton_mamba.tasks.motion.formats.mp4 import write_mp4
from skeleton_mamba.tasks.motion.io.value_checks import check_fps
from skeleton_mamba.tasks.motion.music.audio_io import read_audio

__all__ = ["RenderStyle", "fit_cameras", "joint_sides", "render_frames", "render_motion", "write_video"]

_AA = cv2.LINE_AA
# "left" / "right" in any case, or a capital L / R prefix before a capital (CMU "LHipJoint").
_LEFT = re.compile(r"(?i:left)|^L(?=[A-Z])")
_RIGHT = re.compile(r"(?i:right)|^R(?=[A-Z])")


@dataclass
class RenderStyle:
    """Image size, camera and colours (RGB) of :func:`render_frames`."""

    width: int = 640
    height: int = 480
    fov_degrees: float = 50.0
    azimuth_degrees: float = 30.0
    elevation_degrees: float = 15.0
    body_fraction: float = 0.6
    margin_fraction: float = 0.08  # every joint of every frame stays this fraction of the height inside
    follow_seconds: float = 0.5
    background: tuple[int, int, int] = (246, 246, 246)
    grid: tuple[int, int, int] = (200, 200, 200)
    shadow: tuple[int, int, int] = (215, 215, 215)
    left: tuple[int, int, int] = (40, 100, 220)
    right: tuple[int, int, int] = (220, 50, 50)
    middle: tuple[int, int, int] = (70, 70, 70)
    bone_thickness: int = 3
    joint_radius: int = 4


def joint_sides(names: Sequence[str]) -> list[int]:
    """-1 for left joints, +1 for right, 0 otherwise, from names (``left_hip``, ``LeftArm``, ``LHip``)."""
    sides = []
    for name in names:
        if _LEFT.search(name) and not _RIGHT.search(name):
            sides.append(-1)
        elif _RIGHT.search(name):
            sides.append(1)
        else:
            sides.append(0)
    return sides


def _smooth(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average along axis 0 with edge padding: (T, C) -> (T, C)."""
    if width <= 1 or len(x) < 2:
        return x
    pad = width // 2
    padded = np.concatenate([np.repeat(x[:1], pad, 0), x, np.repeat(x[-1:], pad, 0)])
    kernel = np.ones(2 * pad + 1) / (2 * pad + 1)
    return np.stack([np.convolve(padded[:, c], kernel, mode="valid") for c in range(x.shape[1])], axis=1)


class _Camera:
    """Pinhole look-at camera; ``project`` maps world points (N, 3) to pixels (N, 2) and depths (N,)."""

    def __init__(self, eye: np.ndarray, target: np.ndarray, focal: float, cx: float, cy: float) -> None:
        forward = target - eye
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, [0.0, 1.0, 0.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        self.rotation = np.stack([right, up, forward])  # world -> camera axes (x right, y up, z forward)
        self.eye, self.target, self.focal, self.cx, self.cy = eye, target, focal, cx, cy

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        return (points - self.eye) @ self.rotation.T

    def pixels(self, cam: np.ndarray) -> np.ndarray:
        z = np.maximum(cam[:, 2], 1e-9)
        return np.stack([self.cx + self.focal * cam[:, 0] / z, self.cy - self.focal * cam[:, 1] / z], axis=1)


def _clip_project(
    camera: _Camera, a: np.ndarray, b: np.ndarray, near: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clip world segments a[i]-b[i] (N, 3) to depth > near; return pixel ends (N, 2) x2 and a keep mask."""
    ca, cb = camera.to_camera(a), camera.to_camera(b)
    keep = (ca[:, 2] > near) | (cb[:, 2] > near)
    # Move an endpoint behind the near plane onto it, along the segment.
    for first, second in ((ca, cb), (cb, ca)):
        behind = keep & (first[:, 2] <= near)
        if behind.any():
            t = (near - first[behind, 2]) / (second[behind, 2] - first[behind, 2])
            first[behind] = first[behind] + t[:, None] * (second[behind] - first[behind])
    return camera.pixels(ca), camera.pixels(cb), keep


def _fixed(points: np.ndarray) -> np.ndarray:
    """Pixels to OpenCV's 4-bit fixed point (sub-pixel anti-aliased drawing with ``shift=4``)."""
    return np.round(np.clip(points, -1e5, 1e5) * 16).astype(np.int32)


def _draw_lines(
    image: np.ndarray, camera: _Camera, a: np.ndarray, b: np.ndarray, near: float, color, thickness: int
) -> None:
    """Draw world segments a[i]-b[i] (N, 3) anti-aliased, clipped to depth > near."""
    pa, pb, keep = _clip_project(camera, a, b, near)
    if keep.any():
        lines = np.stack([_fixed(pa[keep]), _fixed(pb[keep])], axis=1)
        cv2.polylines(image, list(lines), False, color, thickness, cv2.LINE_AA, shift=4)


def _grid_spacing(size: float) -> float:
    """A round spacing (1, 2 or 5 times a power of ten) of about half the body size."""
    target = max(size, 1e-9) / 2
    power = 10 ** math.floor(math.log10(target))
    return min((m * power for m in (1, 2, 5, 10)), key=lambda s: abs(math.log(s / target)))


def _check_joints(joints: np.ndarray, parents: Sequence[int]) -> np.ndarray:
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[2] != 3 or joints.shape[1] != len(parents) or len(joints) == 0:
        raise ValueError(f"joints must be (T>0, {len(parents)}, 3) for the given parents, got {joints.shape}")
    if not np.all(np.isfinite(joints)):
        raise ValueError("joints contain NaN or infinite values")
    return joints


def _clip_size(joints: np.ndarray) -> float:
    """The tallest vertical extent of one frame (T, J, 3) -> float: the body's size (metres for a human)."""
    return max(float((joints[..., 1].max(axis=1) - joints[..., 1].min(axis=1)).max()), 1e-6)


def fit_cameras(
    joints: np.ndarray, parents: Sequence[int], fps: float, style: RenderStyle | None = None
) -> list[_Camera]:
    """One camera per frame of ``joints`` (T, J, 3), y-up, fitted to the whole clip (module docstring).

    All cameras share the viewing direction (azimuth, elevation) and the distance ``d``; they look at
    ``target_t`` = (smoothed root x, middle of the clip's y range, smoothed root z). In the camera axes a
    point is ``q + (0, 0, d)`` with ``q = R (p - target_t)``, so it projects inside the frame with a margin
    of ``m`` pixels when ``f |q_x| / (q_z + d) <= W / 2 - m`` and ``f |q_y| / (q_z + d) <= H / 2 - m``:
    ``d`` is the largest of these bounds over all joints and frames, the near-plane bound and the
    distance at which the tallest pose fills ``body_fraction`` of the height.
    """
    style = style or RenderStyle()
    joints = _check_joints(joints, parents)
    root = list(parents).index(-1) if -1 in parents else 0
    size = _clip_size(joints)
    focal = style.height / (2 * math.tan(math.radians(style.fov_degrees) / 2))
    az, el = math.radians(style.azimuth_degrees), math.radians(style.elevation_degrees)
    direction = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
    follow = _smooth(joints[:, root, [0, 2]], max(1, round(style.follow_seconds * fps)))
    middle = 0.5 * (joints[..., 1].min() + joints[..., 1].max())
    targets = np.stack([follow[:, 0], np.full(len(joints), middle), follow[:, 1]], axis=1)  # (T, 3)
    rotation = _Camera(direction, np.zeros(3), focal, 0.0, 0.0).rotation  # shared by every frame
    q = np.einsum("tjc,kc->tjk", joints - targets[:, None], rotation).reshape(-1, 3)  # (T*J, 3)
    margin = style.margin_fraction * style.height
    half_w, half_h = style.width / 2 - margin, style.height / 2 - margin
    if min(half_w, half_h) <= 0:
        raise ValueError(
            f"margin_fraction {style.margin_fraction} leaves no room in {style.width}x{style.height}"
        )
    near = 0.05 * size
    distance = max(
        size / (style.body_fraction * style.height / focal),
        float(np.max(focal * np.abs(q[:, 0]) / half_w - q[:, 2])),
        float(np.max(focal * np.abs(q[:, 1]) / half_h - q[:, 2])),
        float(np.max(2 * near - q[:, 2])),
    )
    cx, cy = style.width / 2, style.height / 2
    return [_Camera(target + distance * direction, target, focal, cx, cy) for target in targets]


def _floor_frames(
    cameras: Sequence[_Camera], joints: np.ndarray, style: RenderStyle
) -> Iterator[tuple[np.ndarray, _Camera]]:
    """For each camera a new image of the background with the floor grid (world-aligned lines around the
    followed root, at the lowest point of ``joints`` (T, J, 3), spaced by the body's size)."""
    floor, size = joints[..., 1].min(), _clip_size(joints)
    spacing = _grid_spacing(size)
    distance = float(np.linalg.norm(cameras[0].eye - cameras[0].target))
    half = 4 * spacing * max(1, round(distance / (4 * spacing)))
    ticks = np.arange(-half, half + spacing / 2, spacing)
    blank = np.empty((style.height, style.width, 3), dtype=np.uint8)
    blank[:] = np.asarray(style.background, dtype=np.uint8)  # filled once: per-frame tuple fills are slow
    for camera in cameras:
        image = blank.copy()
        gx = spacing * np.round(camera.target[0] / spacing) + ticks
        gz = spacing * np.round(camera.target[2] / spacing) + ticks
        one = np.ones_like(gx)
        lines_x = [np.stack([gx, floor * one, gz[i] * one], 1) for i in (0, -1)]  # along z, one per x
        lines_z = [np.stack([gx[i] * one, floor * one, gz], 1) for i in (0, -1)]  # along x, one per z
        a, b = np.concatenate([lines_x[0], lines_z[0]]), np.concatenate([lines_x[1], lines_z[1]])
        _draw_lines(image, camera, a, b, 0.05 * size, style.grid, 1)
        yield image, camera


def _time_label(image: np.ndarray, seconds: float, title: str | None) -> None:
    label = f"{seconds:6.2f} s" + (f"   {title}" if title else "")
    cv2.putText(image, label, (10, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (60, 60, 60), 1, cv2.LINE_AA)


def render_frames(
    joints: np.ndarray,
    parents: Sequence[int],
    fps: float,
    names: Sequence[str] | None = None,
    style: RenderStyle | None = None,
    title: str | None = None,
) -> Iterator[np.ndarray]:
    """Yield one (H, W, 3) uint8 RGB image per frame of ``joints`` (T, J, 3), y-up."""
    style = style or RenderStyle()
    joints = _check_joints(joints, parents)
    sides = joint_sides(names) if names is not None else [0] * len(parents)
    colors = {-1: style.left, 1: style.right, 0: style.middle}
    bones = np.array([(p, j) for j, p in enumerate(parents) if p >= 0], dtype=np.int64).reshape(-1, 2)
    cameras = fit_cameras(joints, parents, fps, style)
    floor, near = joints[..., 1].min(), 0.05 * _clip_size(joints)
    thickness, radius = style.bone_thickness, style.joint_radius * 16
    for t, (image, camera) in enumerate(_floor_frames(cameras, joints, style)):
        frame = joints[t]
        shadow = frame.copy()
        shadow[:, 1] = floor
        _draw_lines(image, camera, shadow[bones[:, 0]], shadow[bones[:, 1]], near, style.shadow, thickness)
        # Bones far-to-near, then joints far-to-near (painter's order).
        pa, pb, keep = _clip_project(camera, frame[bones[:, 0]], frame[bones[:, 1]], near)
        pa, pb = _fixed(pa), _fixed(pb)
        cam = camera.to_camera(frame)
        for k in np.argsort(-(cam[bones[:, 0], 2] + cam[bones[:, 1], 2])):
            if keep[k]:
                color = colors[sides[bones[k, 1]]]
                cv2.line(image, tuple(pa[k].tolist()), tuple(pb[k].tolist()), color, thickness, _AA, 4)
        pix = _fixed(camera.pixels(cam))
        for j in np.argsort(-cam[:, 2]):
            if cam[j, 2] > near:
                cv2.circle(image, tuple(pix[j].tolist()), radius, colors[sides[j]], -1, _AA, 4)
        _time_label(image, t / fps, title)
        yield image


def _write_gif(out: Path, frames: list[np.ndarray], fps: float) -> None:
    """Write RGB frames as a looping GIF with one shared 256-colour palette (no dithering).

    One palette (median cut over up to 8 sampled frames) is much faster than a palette per frame and
    suits the few flat colours drawn here. GIF delays are whole 1/100 s, so 30 fps plays at ~30.3 fps.
    """

    samples = frames[:: max(1, len(frames) // 8)][:8]
    palette = Image.fromarray(np.concatenate(samples, axis=0)).quantize(256, method=Image.Quantize.MEDIANCUT)
    images = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
    images[0].save(out, save_all=True, append_images=images[1:], duration=round(1000 / fps), loop=0)


def render_motion(
    joints: np.ndarray,
    parents: Sequence[int],
    out: str | PathLike[str],
    fps: float,
    music: str | PathLike[str] | None = None,
    names: Sequence[str] | None = None,
    style: RenderStyle | None = None,
    title: str | None = None,
    progress: bool = True,
) -> Path:
    """Render joint positions (T, J, 3), y-up, to ``out`` (``.mp4`` or ``.gif``).

    Args:
        joints: (T, J, 3) joint positions, one frame per output frame (resample first to change fps).
        parents: J parent indices (``-1`` for the root) defining the bones.
        out: output path; the suffix picks the format.
        fps: frame rate of ``joints`` and of the video.
        music: audio file muxed into an mp4 (AAC, cut to the motion's length); ignored for GIF.
        names: J joint names, for left/right colouring.
        style: image size, camera and colours.
        title: text drawn after the time stamp.
        progress: show a tqdm bar.

    Returns:
        The written path.
    """
    style = style or RenderStyle()
    joints = _check_joints(joints, parents)  # fail before an output file is opened
    return write_video(
        lambda: render_frames(joints, parents, fps, names=names, style=style, title=title),
        len(joints), out, fps, music, style, progress,
    )  # fmt: skip


def write_video(
    frames: Callable[[], Iterable[np.ndarray]],
    count: int,
    out: str | PathLike[str],
    fps: float,
    music: str | PathLike[str] | None = None,
    style: RenderStyle | None = None,
    progress: bool = True,
) -> Path:
    """The ``count`` images that ``frames()`` yields written to ``out`` (``.mp4`` with ``music`` muxed, or a
    looping ``.gif``), atomically; everything is checked (suffix, frame rate, music, size) before
    ``frames`` is called."""
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".mp4", ".gif"):
        raise ValueError(f"{out}: output must end in .mp4 or .gif")
    check_fps(fps, "fps")  # bounds the camera smoothing window (it grows with fps)
    check_writable(out)
    style = style or RenderStyle()
    sound = None
    if music is not None and suffix == ".mp4":  # decoded and checked before anything is written
        sound = read_audio(music, duration_s=count / fps, mono=False)
    if suffix == ".mp4" and (style.width % 16 or style.height % 16):
        raise ValueError(f"mp4 width and height must be multiples of 16, got {style.width}x{style.height}")
    frames = tqdm(frames(), total=count, desc=f"render {out.name}", unit="frame", disable=not progress)
    if suffix == ".gif":
        if music is not None:
            warnings.warn(f"{out}: GIF has no audio track, music ignored", stacklevel=2)
        with atomic_path(out) as tmp:
            _write_gif(tmp, list(frames), fps)
        return out
    with atomic_path(out) as tmp:
        _write_mp4(tmp, frames, fps, style, sound, target=out)
    return out


def _write_mp4(
    out: Path,
    frames: Iterable[np.ndarray],
    fps: float,
    style: RenderStyle,
    sound: tuple[np.ndarray, int] | None,
    target: Path,
) -> None:
    """Encode the frames with :func:`skeleton_mamba.tasks.motion.formats.mp4.write_mp4`; ``sound`` ``((N, C)
    samples, rate)`` goes in as AAC.

    The samples (already checked by :mod:`skeleton_mamba.tasks.motion.music.audio_io`, cut to the motion's
    length) are written as a temporary 32-bit float WAV beside ``out`` for ffmpeg to mux, and removed
    afterwards.
    """
    if sound is None:
        write_mp4(out, frames, (style.width, style.height), fps, target=target)
        return
    fd, wav = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=".wav", dir=out.parent)
    os.close(fd)
    try:
        soundfile.write(wav, sound[0], sound[1], subtype="FLOAT")
        write_mp4(out, frames, (style.width, style.height), fps, audio_wav=wav, target=target)
    finally:
        Path(wav).unlink(missing_ok=True)
