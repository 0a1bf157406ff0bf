"""H.264 mp4 encoding with the ffmpeg binary of imageio-ffmpeg, checked: exit status, error output, streams.

Every mp4 the project writes goes through :func:`write_mp4`. ffmpeg reads raw RGB frames on a pipe and, when
sound is asked for, a PCM WAV the caller wrote from already checked samples
(:mod:`skeleton_mamba.tasks.motion.music.audio_io`), so ffmpeg never decodes outside audio itself. The file is
accepted only when ffmpeg exited with status 0, printed no error, and the written file holds a video stream
and, when sound was asked for, an audio stream; otherwise :class:`Mp4WriteError` (an ``OSError`` naming the
file, one line: ``sm`` exits 2) says what ffmpeg reported. A pipe that breaks mid-video (ffmpeg died) is
reported the same way, with ffmpeg's own last words.

The caller writes to a temporary path beside the target (:func:`.atomic.atomic_path`), so a refused file
never replaces an old one.
"""

from __future__ import annotations

import errno
import subprocess
import tempfile
from collections.abc import Iterable
from fractions import Fraction
from pathlib import Path

import imageio_ffmpeg
import numpy as np

__all__ = ["CRF", "Mp4WriteError", "write_mp4"]

CRF = 15  # x264 constant rate factor (imageio-ffmpeg's quality 7 of 10)


class Mp4WriteError(OSError):
    """ffmpeg failed or wrote an mp4 without the streams asked for; ``filename`` is the target."""


def _last_words(stderr: str) -> str:
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    return lines[-1] if lines else "no message"


def _fail(target: Path, reason: str) -> Mp4WriteError:
    return Mp4WriteError(errno.EIO, reason, str(target))


def _has_stream(path: Path, kind: str) -> bool:
    """Whether ``path`` holds a decodable stream of ``kind`` (``"v"`` or ``"a"``): a stream copy to null."""
    probe = [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path), "-map", f"0:{kind}:0",
             "-c", "copy", "-f", "null", "-"]  # fmt: skip
    result = subprocess.run(probe, capture_output=True, text=True, stdin=subprocess.DEVNULL)
    return result.returncode == 0 and not result.stderr.strip()


def write_mp4(
    out: str | Path,
    frames: Iterable[np.ndarray],
    size: tuple[int, int],
    fps: float,
    audio_wav: str | Path | None = None,
    target: str | Path | None = None,
    preset: str = "veryfast",
    crf: int = CRF,
    pix_fmt: str = "yuv420p",
) -> int:
    """Encode ``(H, W, 3)`` uint8 RGB ``frames`` to ``out`` (H.264, yuv420p), muxing ``audio_wav`` as AAC.

    Args:
        out: the file to write (a temporary path beside ``target``).
        frames: RGB frames of ``size``.
        size: ``(width, height)`` (even for yuv420p; the renderer uses multiples of 16).
        fps: frame rate.
        audio_wav: a PCM WAV to mux (written by the caller from checked samples), or ``None``: no sound.
        target: the path named in errors (default ``out``).
        preset: x264 preset.
        crf: x264 constant rate factor (0 lossless - 51 worst).
        pix_fmt: encoded pixel format (``yuv420p`` plays everywhere and needs even sizes; ``yuv444p``).

    Returns:
        The number of frames written.

    Raises:
        Mp4WriteError: ffmpeg exited with an error, reported one, or the file lacks the video or the
            sound stream; also when no frame was given.
    """
    out, target = Path(out), Path(target if target is not None else out)
    width, height = size
    rate = str(Fraction(fps).limit_denominator())  # as a rational: 24000/1001 is not rounded
    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-nostdin", "-v", "error",
           "-f", "rawvideo", "-vcodec", "rawvideo", "-s", f"{width}x{height}", "-pix_fmt", "rgb24",
           "-r", rate, "-i", "-"]  # fmt: skip
    if audio_wav is not None:
        cmd += ["-i", str(audio_wav), "-map", "0:v:0", "-map", "1:a:0", "-c:a", "aac"]
    else:
        cmd += ["-an"]
    cmd += ["-c:v", "libx264", "-pix_fmt", pix_fmt, "-crf", str(int(crf)), "-preset", preset, str(out)]
    count = 0
    with tempfile.TemporaryFile() as log:  # a file, not a pipe: ffmpeg never blocks on its own messages
        # its own session: Ctrl-C reaches only us, and we stop ffmpeg (its messages stay in the log)
        process = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log, start_new_session=True
        )
        broken = False
        try:
            for image in frames:
                image = np.ascontiguousarray(image, dtype=np.uint8)
                if image.shape != (height, width, 3):
                    raise ValueError(
                        f"{target}: frame {count} is {image.shape}, expected {(height, width, 3)}"
                    )
                try:
                    process.stdin.write(image.tobytes())
                except BrokenPipeError:  # ffmpeg exited; its log says why
                    broken = True
                    break
                count += 1
            try:
                process.stdin.close()
            except BrokenPipeError:
                broken = True
            code = process.wait()
        except BaseException:  # Ctrl-C or a drawing error: stop ffmpeg, the caller removes the file
            process.kill()
            process.wait()
            raise
        log.seek(0)
        stderr = log.read().decode("utf-8", "replace")
    if broken or code != 0:
        what = f"ffmpeg stopped after {count} frames" if broken else f"ffmpeg failed (exit status {code})"
        raise _fail(target, f"{what}: {_last_words(stderr)}")
    if stderr.strip():
        raise _fail(target, f"ffmpeg reported an error: {_last_words(stderr)}")
    if count == 0:
        raise _fail(target, "no frames to encode")
    if not _has_stream(out, "v"):
        raise _fail(target, "ffmpeg wrote no video stream")
    if audio_wav is not None and not _has_stream(out, "a"):
        raise _fail(target, "ffmpeg wrote no sound stream, though music was asked for")
    return count
