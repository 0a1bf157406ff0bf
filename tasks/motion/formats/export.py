"""Write an SMPL-24 motion as files: our motion ``.npz``, a BVH, a glTF ``.glb`` and an mp4 rendering with the
music muxed in.

Used by every task that writes dances (``sm dance``, the EgoMusic demo, ``sm stream``). The music of the
rendering is the slice of the track the motion was made for (``music_start_s``), cut to the motion's length
and written next to the video as a wav, so that the mp4's audio starts where the motion starts.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import soundfile as sf

from skeleton_mamba.io.atomic import atomic_path
from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.formats.bvh import save_bvh, smpl_to_bvh
from skeleton_mamba.tasks.motion.formats.gltf import from_motion_data, write_glb
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion
from skeleton_mamba.tasks.motion.music.audio_io import read_audio
from skeleton_mamba.tasks.motion.render.skeleton import RenderStyle, render_motion

__all__ = ["DanceFiles", "dance_files", "write_motion", "write_music_slice"]


def dance_files(name: str, render: bool = True) -> list[str]:
    """The names :func:`write_motion` writes for ``name`` (``render``: the mp4 and the music slice too)."""
    return [f"{name}{suffix}" for suffix in (".npz", ".bvh", ".glb", *((".mp4", ".wav") if render else ()))]


@dataclass
class DanceFiles:
    """Paths of one written dance (``mp4``/``wav`` None when not rendered / no music; ``rig``: the dance on a
    character, written by the command with ``--rig``)."""

    npz: Path
    bvh: Path
    glb: Path | None = None
    mp4: Path | None = None
    wav: Path | None = None
    rig: Path | None = None

    def lines(self) -> list[str]:
        return [f"  {kind:4s} {path}" for kind, path in vars(self).items() if path is not None]


def write_music_slice(src: str | Path, start_s: float, duration_s: float, out: str | Path) -> Path:
    """Write ``duration_s`` seconds of the audio file ``src`` from ``start_s`` as 16-bit mono wav at ``out``.

    Read by the one checked reader (:func:`skeleton_mamba.tasks.motion.music.audio_io.read_audio`): only the
    slice is decoded.
    """
    audio, sr = read_audio(src, offset_s=max(0.0, start_s), duration_s=duration_s)
    out = Path(out)
    with atomic_path(out) as tmp:
        sf.write(tmp, np.clip(audio, -1.0, 1.0), sr, subtype="PCM_16")
    return out


def write_motion(
    motion: MotionData,
    out_dir: str | Path,
    name: str,
    music: str | Path | None = None,
    music_start_s: float = 0.0,
    render: bool = True,
    style: RenderStyle | None = None,
    title: str | None = None,
    progress: bool = False,
) -> DanceFiles:
    """An SMPL-24 :class:`MotionData` (with joints) -> ``<name>.npz / .bvh / .glb / .mp4`` in ``out_dir``.

    Args:
        motion: the motion, with its joints (T, 24, 3).
        out_dir: output folder (created).
        name: file stem.
        music: the audio file the motion was made for (None: a silent video).
        music_start_s: where in ``music`` the motion starts.
        render: write the mp4.
        style: image size and colours of the rendering.
        title: text drawn on the video.
        progress: show a rendering progress bar.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fps = motion.fps
    files = DanceFiles(
        npz=save_motion(out_dir / f"{name}.npz", motion),
        bvh=save_bvh(out_dir / f"{name}.bvh", smpl_to_bvh(motion.poses, motion.trans, fps)),
        glb=write_glb(from_motion_data(motion), out_dir / f"{name}.glb", name=name),
    )
    if render:
        if music is not None:
            duration = motion.num_frames / fps
            files.wav = write_music_slice(music, music_start_s, duration, out_dir / f"{name}.wav")
        files.mp4 = render_motion(
            np.asarray(motion.joints),
            SMPL24.parents,
            out_dir / f"{name}.mp4",
            fps,
            music=files.wav,
            names=SMPL24.joint_names,
            style=style,
            title=title,
            progress=progress,
        )
    return files
