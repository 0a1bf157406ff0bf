"""Hostile egocentric videos for ``sm dance --video`` (issue 33): refused on one line (exit 2, no traceback),
or, for a video whose frame size changes midway, read at one size."""

import subprocess
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.egodance.frames import iter_video_frames
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.checkpoint_files import save_module_checkpoint

FFMPEG = imageio_ffmpeg.get_ffmpeg_exe()


def _write(path: Path, num_frames: int, width: int, height: int, *params: str) -> Path:
    writer = imageio_ffmpeg.write_frames(
        str(path), (width, height), fps=30, macro_block_size=16, output_params=list(params)
    )
    writer.send(None)
    for t in range(num_frames):
        writer.send(np.full((height, width, 3), (t * 9) % 256, np.uint8))
    writer.close()
    return path


def _ffmpeg(*args: str) -> None:
    subprocess.run([FFMPEG, "-y", "-loglevel", "error", *args], check=True, timeout=60)


def _audio_only(path: Path) -> Path:  # an mp4 with no video stream: zero frames
    _ffmpeg("-f", "lavfi", "-i", "sine=d=1", "-c:a", "aac", str(path))
    return path


def _zero_frames(path: Path) -> Path:  # a video stream holding no frame
    _ffmpeg("-f", "lavfi", "-i", "color=c=red:s=64x48:d=1", "-frames:v", "0", str(path))
    return path


def _cut(path: Path, *params: str) -> Path:  # the first half of a valid file
    data = _write(path.with_name("whole" + path.name), 60, 64, 48, *params).read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def _empty(path: Path) -> Path:
    path.write_bytes(b"")
    return path


CASES = {
    "empty_file": _empty,
    "audio_only": _audio_only,
    "zero_frames": _zero_frames,
    "truncated_moov_at_end": _cut,  # the index (moov) is lost
    "truncated_faststart": lambda p: _cut(p, "-movflags", "+faststart"),  # index kept, frames cut
}


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory, tiny_egodance_module):
    tmp = tmp_path_factory.mktemp("fuzz_video")
    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

    torch.manual_seed(0)
    module = tiny_egodance_module()
    path = tmp / "emm.ckpt"
    save_module_checkpoint(module, path)
    return path, write_music(tmp / "song.wav", synthesize_music(120.0, 2.0))


@pytest.mark.parametrize("case", sorted(CASES))
def test_sm_dance_refuses_unreadable_videos_on_one_line(tmp_path, ckpt, case, capsys):
    checkpoint, wav = ckpt
    video = tmp_path / "ego.mp4"
    CASES[case](video)
    out = tmp_path / "out"
    argv = ["dance", "--ckpt", str(checkpoint), "--music", str(wav), "--video", str(video), "--out", str(out)]
    assert sm_main([*argv, "--steps", "1", "--no-render"]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert str(video) in lines[0] and "video" in lines[0], lines[0]
    assert not out.exists()


def test_a_video_whose_frame_size_changes_midway_is_read_at_the_first_size(tmp_path):
    """Two H.264 streams, 64x48 then 96x64, joined: ffmpeg scales the second part to the first's size, so
    every frame reaches the model (a folder of images of two sizes is refused:
    tests/motion/io/test_fuzz_motion.py)."""
    parts = []
    for name, (w, h) in {"a": (64, 48), "b": (96, 64)}.items():
        mp4 = _write(tmp_path / f"{name}.mp4", 20, w, h)
        parts.append(tmp_path / f"{name}.ts")
        _ffmpeg("-i", str(mp4), "-c", "copy", "-bsf:v", "h264_mp4toannexb", str(parts[-1]))
    joined = tmp_path / "joined.mp4"
    _ffmpeg("-i", "concat:" + "|".join(map(str, parts)), "-c", "copy", str(joined))
    chunks = list(iter_video_frames(joined, (48, 64), chunk=16))
    frames = torch.cat(chunks)
    assert frames.shape == (40, 3, 48, 64)
    written = torch.tensor([(t * 9) % 256 for t in range(20)] * 2, dtype=torch.float32) / 255.0
    torch.testing.assert_close(frames.mean((1, 2, 3)), written, atol=3 / 255, rtol=0)  # flat grey frames
