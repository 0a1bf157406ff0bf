"""What ``sm dance`` samples a dance from: the music's features, the egocentric video reduced to per-frame
features, the head-guidance targets, and, for a held-out sample, its ground truth.

A user's track (``--music`` + ``--video``) and a sample folder (``--sample``, any length) go the same way: the
video is decoded as a stream at the model's resolution and frame rate (:func:`.video_features.encode_video`; a
video of another rate is taken at the model's, frames dropped or repeated), so memory does not grow with its
length. What the dance covers is decided from the headers before anything is decoded: the music's length, or
the video's when it is shorter (said on one line, before the decoding starts: the dance then covers the part
where both are).

The head targets are then chosen by :func:`.long_form.head_targets`.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.egodance.data import EgoDanceDataset
from skeleton_mamba.tasks.egodance.frames import video_header
from skeleton_mamba.tasks.egodance.long_form import LongForm
from skeleton_mamba.tasks.egodance.sampling import sample_long_dance
from skeleton_mamba.tasks.egodance.video_features import VideoFeatures, encode_video
from skeleton_mamba.tasks.egodance.video_rotation import HeadRotationStream, intrinsics_for, scale_intrinsics
from skeleton_mamba.tasks.motion.io.value_checks import load_npz
from skeleton_mamba.tasks.motion.music.audio_io import probe_audio
from skeleton_mamba.tasks.motion.music.features import extract_music_features

__all__ = ["DanceInputs", "sample_inputs", "track_inputs"]


@dataclass
class DanceInputs:
    """Attributes:
    music: (T, L) music features at the model's rate.
    video: the video's per-frame features (vision z_v, head-estimator features), or None (music-only).
    truth: (T, 24, 10) a sample's ground-truth motion tokens in its canonical frame, or None.
    head: (T, 3) a sample's ground-truth head positions in that frame, or None.
    music_path, music_start_s: the audio the dance is sampled for (muxed into the mp4).
    seconds: wall seconds of each stage that made them (``music features``, ``video``), for ``sm dance``'s
    timing line.
    """

    music: torch.Tensor
    video: VideoFeatures | None
    truth: torch.Tensor | None = None
    head: torch.Tensor | None = None
    music_path: str | None = None
    music_start_s: float = 0.0
    seconds: dict[str, float] = field(default_factory=dict)

    def dance(self, model: torch.nn.Module, diffusion, long_form: LongForm, **kwargs) -> torch.Tensor:
        """:func:`.sampling.sample_long_dance` of these inputs (the music, the video's features and the
        head's turns read from it) in ``long_form``'s windows; ``kwargs``: its other arguments."""
        video = self.video
        return sample_long_dance(
            model,
            diffusion,
            self.music,
            headings=None if video is None else video.heading,
            vision=None if video is None else video.vision,
            window=long_form.window,
            overlap=long_form.overlap,
            canonical=long_form.canonical,
            **kwargs,
        )


ROTATION_SIZE = 64
"""Frames are aligned for the head's rotation at most this many pixels across (:mod:`.video_rotation`)."""


def rotation_stream(image_size: int, K: torch.Tensor) -> HeadRotationStream:
    """A rotation tracker for frames decoded at ``image_size`` whose intrinsics there are ``K``."""
    size = min(image_size, ROTATION_SIZE)
    return HeadRotationStream(scale_intrinsics(K, size / image_size, size / image_size), size)


def _encode(
    video: Path,
    module,
    model,
    frames: int,
    long_form: LongForm,
    estimate: bool,
    progress: bool,
    K: torch.Tensor | None = None,
):
    """``K``: the frames' intrinsics at the model's image size, for the head's rotation (None: not tracked;
    only models whose windows face their first heading use it)."""
    size = module.hparams.image_size
    rotation = rotation_stream(size, K) if K is not None and long_form.canonical else None
    return encode_video(
        video,
        size,
        model.vision_encoder,
        module.head_estimator if estimate else None,
        window=long_form.window,
        max_frames=frames,
        progress=progress,
        hops=(long_form.hop,),  # every long-form window's start, for its own head estimate
        fps=float(module.hparams.fps),
        rotation=rotation,
    )


def track_inputs(
    music: str,
    video: str | None,
    module,
    model,
    long_form: LongForm,
    estimate: bool,
    progress: bool = False,
    fov: float | None = 90.0,
) -> DanceInputs:
    """A user's track: the music file and, for a vision model, the egocentric video (file or image folder).

    ``fov``: the camera's horizontal field of view (degrees) for reading the head's turns from the video
    (:mod:`.video_rotation`; the video's aspect from its header), or None: not read.

    The video's length is read from its header first: when it is shorter than the music the dance covers
    the video's part, and a warning says so before the decoding starts.
    """
    fps = float(module.hparams.fps)
    music_s = probe_audio(music).duration_s  # the header's checks first; nan: a stream of unknown length
    if model.vision_encoder is not None and not video:
        raise InputError(f"the model conditions on egocentric video: pass --video with --music {music}")
    header = video_header(video) if model.vision_encoder is not None else None
    covered = None if header is None else header.frames_at(fps)
    music_frames = None if math.isnan(music_s) else 1 + int(music_s * fps)  # centred frames, as analysed
    start = time.perf_counter()
    # only the music the video covers is analysed (a second more: a header can be off by a frame)
    longer = covered is not None and music_frames is not None and music_frames - covered > 1
    duration = covered / fps + 1.0 if longer else None
    analysis = extract_music_features(music, fps=fps, duration_s=duration)
    features = torch.from_numpy(analysis.features.astype(np.float32))
    seconds = {"music features": time.perf_counter() - start}
    if header is None:
        return DanceInputs(features, None, music_path=music, seconds=seconds)
    if header.fps is not None and abs(header.fps - fps) > 1e-3 * fps:
        print(f"sm dance: {video}: a {header.fps:g} fps video, taken at the model's {fps:g} fps "
              "(frames dropped or repeated)", file=sys.stderr)  # fmt: skip
    if longer:  # one frame of rounding is no news
        print(
            f"sm dance: warning: the video has {covered} frames ({covered / fps:.1f} s at {fps:g} fps), the "
            f"music {music_frames} ({music_frames / fps:.1f} s); the dance covers the first "
            f"{covered / fps:.1f} s, where both are (pass a video as long as the music for the whole track)",
            file=sys.stderr,
        )
    start = time.perf_counter()
    size = module.hparams.image_size
    aspect = header.width / header.height if header.width and header.height else 1.0
    K = None if fov is None else intrinsics_for(size, fov, aspect)
    encoded = _encode(Path(video), module, model, len(features), long_form, estimate, progress, K)
    seconds["video"] = time.perf_counter() - start  # decoding, the vision encoder, the head estimator
    n = encoded.num_frames  # at most len(music); the header can be off by a frame or two
    if covered is None and len(features) - n > 1:
        print(f"sm dance: warning: the video has {n} frames, the music {len(features)}; the dance covers the "
              f"first {n / fps:.1f} s, where both are", file=sys.stderr)  # fmt: skip
    return DanceInputs(features[:n], encoded, music_path=music, seconds=seconds)


def sample_inputs(
    folder: str,
    module,
    model,
    long_form: LongForm,
    estimate: bool,
    progress: bool = False,
    heading: bool = True,
) -> DanceInputs:
    """An EgoAIST++ sample folder of any length: its music slice, the features of its egocentric video, its
    ground-truth motion and head path (in the sample's canonical frame, as the data module reads them);
    ``heading``: the head's turns read from the video with the sample's camera intrinsics."""
    folder = Path(folder)
    camera = load_npz(folder / "camera.npz")
    frames = len(camera["positions"])
    item = EgoDanceDataset(
        [folder],
        window=frames,
        fps=int(module.hparams.fps),
        load_frames=False,
        canonicalize_init_head=long_form.canonical,
    )[0]
    video = None
    if model.vision_encoder is not None:
        rgb = folder / "rgb.mp4" if (folder / "rgb.mp4").is_file() else folder / "rgb"
        size = module.hparams.image_size  # the rendered intrinsics, scaled to the decoded frames
        width, height = float(camera["width"]), float(camera["height"])
        K = scale_intrinsics(torch.from_numpy(camera["K"]), size / width, size / height)
        video = _encode(rgb, module, model, frames, long_form, estimate, progress, K if heading else None)
        if video.num_frames < frames:
            raise InputError(f"{rgb}: {video.num_frames} frames, the sample's camera path {frames}")
    return DanceInputs(
        item["music"], video, item["motion"], item["head"], item["music_path"], item["music_start_s"]
    )
