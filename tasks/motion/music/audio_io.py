"""The one audio reader of every command: bounded headers, chunked decoding, checked samples.

``sm analyze-music``, ``sm dance --music``, ``sm render --music``, ``sm stream`` (files and standard input)
and the music features of the data modules all read audio here, so every one of them refuses the same hostile
files with the same one-line :class:`AudioFileError` (a :class:`~.errors.DataFileError`: ``sm`` exits 2).

Before anything is allocated the header is checked against stated bounds:

========================  =====================================================================
sample rate               :data:`MIN_SAMPLE_RATE` - :data:`MAX_SAMPLE_RATE` Hz (8 kHz - 192 kHz)
channels                  1 - :data:`MAX_CHANNELS` (8)
duration                  at most :data:`MAX_DURATION_S` (one hour), from the header, before decoding
WAV encodings             PCM 8 (unsigned), 16, 24 and 32-bit, float 32 and 64-bit (also as
                          WAVE_FORMAT_EXTENSIBLE); other WAV encodings and other formats (FLAC,
                          Ogg Vorbis/Opus, MP3, ...) through libsndfile (``soundfile``)
========================  =====================================================================

WAV files are parsed here (a sequential RIFF walk, so a pipe works the same): a data chunk that claims more
bytes than the file holds, or a file cut inside a frame, is read up to the last whole frame with an
:class:`AudioWarning` that says how much was read; bytes after a data chunk that claims less than the file
holds and are no RIFF chunk are ignored with the same kind of warning. An unknown length (``0`` or
``0xFFFFFFFF``, as streaming writers leave it) means "to the end". Other formats are decoded by
libsndfile block by block; a decode error names the time it happened at, and a stream that ends early is
read up to there with a warning.

Samples are decoded in blocks of :data:`BLOCK_FRAMES` frames and checked as they come: NaN, Inf or a
magnitude above :data:`MAX_ABS_SAMPLE` (float audio lies in [-1, 1]; a little headroom is ordinary, 1e38 is
corruption) stops with the time and byte offset of the first. Memory is the output array (one hour of mono
float32 at 48 kHz is 0.7 GB) plus one block; nothing else grows with the file.
"""

from __future__ import annotations

import math
import os
import struct
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
import soundfile

from skeleton_mamba.errors import DataFileError

__all__ = [
    "BLOCK_FRAMES",
    "MAX_ABS_SAMPLE",
    "MAX_CHANNELS",
    "MAX_DURATION_S",
    "MAX_SAMPLE_RATE",
    "MIN_SAMPLE_RATE",
    "AudioFileError",
    "AudioInfo",
    "AudioReader",
    "AudioWarning",
    "check_format",
    "open_audio",
    "open_wav_stream",
    "probe_audio",
    "read_audio",
]

MIN_SAMPLE_RATE = 8_000
MAX_SAMPLE_RATE = 192_000
MAX_CHANNELS = 8
MAX_DURATION_S = 3600.0  # one hour: longer than any dance track; bounds every allocation that scales with it
MAX_ABS_SAMPLE = 8.0  # +18 dBFS of headroom for float audio; beyond it the file is corrupt
BLOCK_FRAMES = 1 << 16
MAX_HEADER_BYTES = 1 << 20  # RIFF chunks before the data chunk (LIST, bext, ...) skipped at most
_UNKNOWN_SIZES = (0, 0xFFFFFFFF)  # data sizes streaming writers leave: read to the end
_PCM, _FLOAT, _EXTENSIBLE = 1, 3, 0xFFFE
_WAV_WIDTHS = {_PCM: (8, 16, 24, 32), _FLOAT: (32, 64)}


class AudioFileError(DataFileError):
    """An audio file or stream is refused: unreadable, outside the bounds, or holding bad samples."""


class AudioWarning(UserWarning):
    """An audio file was read only in part (truncated, or its header and data disagree); says how much."""


@dataclass(frozen=True)
class AudioInfo:
    """What a header says, after the checks.

    Attributes:
        name: the file path, or ``"standard input"``.
        sample_rate: Hz, within the bounds.
        channels: 1 to :data:`MAX_CHANNELS`.
        frames: frames that can be read (``None`` for a stream of unknown length).
        encoding: e.g. ``"PCM 16-bit"``, ``"float 32-bit"``, ``"VORBIS"``.
    """

    name: str
    sample_rate: int
    channels: int
    frames: int | None
    encoding: str

    @property
    def duration_s(self) -> float:
        """Length in seconds (``nan`` for a stream of unknown length)."""
        return math.nan if self.frames is None else self.frames / self.sample_rate


def check_format(name: str, sample_rate: float, channels: int, frames: int | None = None) -> None:
    """Raise :class:`AudioFileError` naming ``name`` when the rate, channels or duration are out of bounds."""
    if not MIN_SAMPLE_RATE <= sample_rate <= MAX_SAMPLE_RATE:
        raise AudioFileError(
            f"{name}: sample rate {sample_rate:g} Hz is outside {MIN_SAMPLE_RATE}-{MAX_SAMPLE_RATE} Hz"
        )
    if not 1 <= channels <= MAX_CHANNELS:
        raise AudioFileError(f"{name}: {channels} channels, audio has 1 to {MAX_CHANNELS}")
    if frames is not None and frames / sample_rate > MAX_DURATION_S:
        raise AudioFileError(
            f"{name}: {frames / sample_rate / 3600:.2f} hours of audio, more than the "
            f"{MAX_DURATION_S / 3600:g} hour a file may hold (MAX_DURATION_S)"
        )


def _clock(seconds: float) -> str:
    return f"{seconds:.3f} s"


def _check_samples(block: np.ndarray, name: str, first_frame: int, rate: int, byte: int | None) -> None:
    """Refuse NaN, Inf and magnitudes above :data:`MAX_ABS_SAMPLE` in a ``(n, channels)`` float block."""
    bad = ~(np.abs(block) <= MAX_ABS_SAMPLE)  # NaN compares False
    if not bad.any():
        return
    frame, channel = np.unravel_index(int(np.flatnonzero(bad)[0]), block.shape)
    value = float(block[frame, channel])
    where = _clock((first_frame + frame) / rate)
    if byte is not None:
        where += f", byte {byte + int(frame) * block.shape[1] * block.itemsize}"
    if math.isnan(value) or math.isinf(value):
        raise AudioFileError(
            f"{name}: audio samples are NaN or Inf, the first ({value:g}) at {where}, channel {channel}"
        )
    raise AudioFileError(
        f"{name}: samples out of range, the first ({value:g}) at {where}, channel {channel}: float audio "
        f"lies in [-1, 1] (up to +-{MAX_ABS_SAMPLE:g} accepted)"
    )


# ----------------------------------------------------------------------------- WAV (files and streams)


@dataclass(frozen=True)
class _WavLayout:
    tag: int  # _PCM or _FLOAT
    bits: int
    channels: int
    rate: int
    data_offset: int  # byte offset of the first sample
    claimed: int | None  # data bytes the header claims (None: unknown)

    @property
    def block_align(self) -> int:
        return self.channels * self.bits // 8

    @property
    def encoding(self) -> str:
        return f"{'PCM' if self.tag == _PCM else 'float'} {self.bits}-bit"


def _read_exact(stream: BinaryIO, n: int) -> bytes:
    data = b""
    while len(data) < n:
        part = stream.read(n - len(data))
        if not part:
            break
        data += part
    return data


def _parse_fmt(body: bytes, name: str) -> tuple[int, int, int, int]:
    """``(tag, channels, rate, bits)`` of a ``fmt `` chunk body, checked."""
    if len(body) < 16:
        raise AudioFileError(f"{name}: WAV fmt chunk of {len(body)} bytes (needs 16)")
    tag, channels, rate, _byte_rate, block_align, bits = struct.unpack("<HHIIHH", body[:16])
    if tag == _EXTENSIBLE:
        if len(body) < 26:
            raise AudioFileError(f"{name}: WAVE_FORMAT_EXTENSIBLE fmt chunk of {len(body)} bytes (needs 26)")
        tag = struct.unpack("<H", body[24:26])[0]  # the first two bytes of the sub-format GUID
    check_format(name, rate, channels)
    if tag in _WAV_WIDTHS and bits not in _WAV_WIDTHS[tag]:
        kind = "PCM" if tag == _PCM else "float"
        widths = "/".join(map(str, _WAV_WIDTHS[tag]))
        raise AudioFileError(f"{name}: {bits}-bit {kind} WAV (reads {widths}-bit {kind})")
    if tag in _WAV_WIDTHS and block_align != channels * bits // 8:
        raise AudioFileError(
            f"{name}: WAV header says {block_align} bytes per frame, {channels} channels of {bits} bits "
            f"make {channels * bits // 8}"
        )
    return tag, channels, rate, bits


def _parse_wav_header(stream: BinaryIO, name: str, what: str = "file") -> _WavLayout | int:
    """Walk the RIFF chunks up to ``data``; returns the layout, or the format tag for libsndfile to decode.

    Reads sequentially (a pipe works); raises :class:`AudioFileError` with the byte offset on a malformed
    header.
    """
    head = _read_exact(stream, 12)
    if len(head) < 12 or head[:4] != b"RIFF" or head[8:12] != b"WAVE":
        kind = {b"RIFX": "a big-endian RIFX file", b"RF64": "an RF64 file"}.get(head[:4], f"not a WAV {what}")
        raise AudioFileError(f"{name}: {kind} (no RIFF/WAVE header)")
    offset, skipped, fmt = 12, 0, None
    while True:
        chunk = _read_exact(stream, 8)
        if len(chunk) < 8:
            raise AudioFileError(f"{name}: the file ends at byte {offset + len(chunk)} before the data chunk")
        chunk_id, size = chunk[:4], struct.unpack("<I", chunk[4:])[0]
        offset += 8
        if chunk_id == b"data":
            if fmt is None:
                raise AudioFileError(f"{name}: data chunk at byte {offset - 8} before any fmt chunk")
            tag, channels, rate, bits = fmt
            if tag not in _WAV_WIDTHS:
                return tag
            claimed = None if size in _UNKNOWN_SIZES else size
            return _WavLayout(tag, bits, channels, rate, offset, claimed)
        skipped += size + (size & 1)
        if skipped > MAX_HEADER_BYTES:
            raise AudioFileError(
                f"{name}: chunk {chunk_id!r} at byte {offset - 8} claims {size} bytes; at most "
                f"{MAX_HEADER_BYTES} bytes of chunks may come before the data"
            )
        body = _read_exact(stream, size + (size & 1))
        if len(body) < size:
            raise AudioFileError(
                f"{name}: chunk {chunk_id!r} at byte {offset - 8} claims {size} bytes, the file ends "
                f"{len(body)} bytes later"
            )
        if chunk_id == b"fmt ":
            fmt = _parse_fmt(body[:size], name)
        offset += len(body)


def _trailing_is_chunks(stream: BinaryIO, start: int, end: int) -> bool:
    """Whether the bytes ``start:end`` of a seekable file are whole RIFF chunks (LIST, id3 after data)."""
    position = start
    while position + 8 <= end:
        stream.seek(position)
        head = stream.read(8)
        if not all(32 <= c < 127 for c in head[:4]):
            return False
        size = struct.unpack("<I", head[4:])[0]
        position += 8 + size + (size & 1)
    return end - position in (0, 1) or position == end


def _decode_wav(data: bytes, layout: _WavLayout) -> np.ndarray:
    """Interleaved little-endian WAV bytes (whole frames) -> ``(n, channels)`` at full scale 1.

    PCM comes back as float32; float WAV as stored (float32 or float64), to be checked before the cast.
    """
    bits, channels = layout.bits, layout.channels
    if layout.tag == _FLOAT:
        # as stored (float32 or float64): the caller checks the values before casting to float32
        return np.frombuffer(data, dtype="<f4" if bits == 32 else "<f8").reshape(-1, channels)
    if bits == 8:
        y = (np.frombuffer(data, dtype=np.uint8).astype(np.float32) - 128.0) / 128.0
    elif bits == 16:
        y = np.frombuffer(data, dtype="<i2").astype(np.float32) / 32768.0
    elif bits == 24:
        b = np.frombuffer(data, dtype=np.uint8).reshape(-1, 3).astype(np.int32)
        v = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16)
        v = np.where(v >= 1 << 23, v - (1 << 24), v)
        y = v.astype(np.float32) / float(1 << 23)
    else:
        y = np.frombuffer(data, dtype="<i4").astype(np.float32) / float(1 << 31)
    return y.reshape(-1, channels)


class AudioReader:
    """Blocks of ``(n, channels)`` float32 samples from one checked source; use as a context manager.

    Made by :func:`open_audio` (a file) or :func:`open_wav_stream` (a WAV stream such as standard input).
    ``info`` holds the checked header. :meth:`blocks` checks every sample as it decodes it.
    """

    def __init__(self, info: AudioInfo, stream: BinaryIO | None = None, layout: _WavLayout | None = None,
                 sound: soundfile.SoundFile | None = None, limit_bytes: int | None = None):  # fmt: skip
        self.info = info
        self._stream, self._layout, self._sound = stream, layout, sound
        self._limit_bytes = limit_bytes  # WAV data bytes to read (None: to the end of the stream)

    def __enter__(self) -> AudioReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._sound is not None:
            self._sound.close()
        if self._stream is not None and self.info.name != "standard input":
            self._stream.close()

    def blocks(
        self, start_frame: int = 0, max_frames: int | None = None, block_frames: int = BLOCK_FRAMES
    ) -> Iterator[np.ndarray]:
        """``(n, channels)`` float32 blocks from ``start_frame`` on, at most ``max_frames`` frames in all.

        A stream of unknown length stops at :data:`MAX_DURATION_S` with an :class:`AudioWarning`.
        """
        rate = self.info.sample_rate
        if max_frames is None:
            max_frames = int(MAX_DURATION_S * rate) if self.info.frames is None else self.info.frames
        if self._limit_bytes is not None:  # a stream whose header claims a plausible length
            max_frames = min(max_frames, max(0, self._limit_bytes // self._layout.block_align - start_frame))
        if self.info.frames is not None:
            max_frames = min(max_frames, max(0, self.info.frames - start_frame))
        if self._sound is not None:
            yield from self._sound_blocks(start_frame, max_frames, block_frames)
            return
        layout, stream = self._layout, self._stream
        align = layout.block_align
        if start_frame:
            if stream.seekable():
                stream.seek(layout.data_offset + start_frame * align)
            else:
                for _ in range(0, start_frame, block_frames):
                    stream.read(min(block_frames, start_frame) * align)
        frame, byte = start_frame, layout.data_offset + start_frame * align
        while frame - start_frame < max_frames:
            want = min(block_frames, max_frames - (frame - start_frame))
            data = _read_exact(stream, want * align)
            whole = len(data) // align * align
            if whole:
                block = _decode_wav(data[:whole], layout)
                if layout.tag == _FLOAT:
                    _check_samples(block, self.info.name, frame, rate, byte)
                yield block.astype(np.float32, copy=False)
            frame, byte = frame + whole // align, byte + whole
            if len(data) < want * align:  # the stream ended
                if self.info.frames is not None or self._limit_bytes is not None:
                    claimed = self.info.frames if self.info.frames is not None else self._limit_bytes // align
                    warnings.warn(
                        f"{self.info.name}: ends at byte {byte + len(data) - whole}, {_clock(frame / rate)} "
                        f"of the {_clock(claimed / rate)} its header claims; read {frame} frames",
                        AudioWarning,
                        stacklevel=2,
                    )
                return
        if self.info.frames is None and self._limit_bytes is None and _read_exact(stream, 1):
            warnings.warn(
                f"{self.info.name}: stopped after {MAX_DURATION_S / 3600:g} hour ({frame} frames, "
                "MAX_DURATION_S); the rest of the stream is ignored",
                AudioWarning,
                stacklevel=2,
            )

    def _sound_blocks(self, start: int, max_frames: int, block_frames: int) -> Iterator[np.ndarray]:
        sound, name, rate = self._sound, self.info.name, self.info.sample_rate
        try:
            if start:
                sound.seek(start)
            done = 0
            while done < max_frames:
                block = sound.read(min(block_frames, max_frames - done), dtype="float32", always_2d=True)
                if not len(block):
                    break
                _check_samples(block, name, start + done, rate, None)
                done += len(block)
                yield block
        except (soundfile.LibsndfileError, RuntimeError) as err:
            raise AudioFileError(
                f"{name}: cannot decode audio at {_clock((start + done) / rate)}: {_reason(err)}"
            ) from err
        if done < max_frames and start + done < (self.info.frames or 0):
            warnings.warn(
                f"{name}: decoding ends at {_clock((start + done) / rate)} of the "
                f"{_clock(self.info.frames / rate)} its header claims; read {start + done} frames",
                AudioWarning,
                stacklevel=2,
            )


def open_wav_stream(stream: BinaryIO, name: str = "standard input") -> AudioReader:
    """An :class:`AudioReader` of a WAV stream read sequentially (standard input, a pipe).

    Any channel count up to :data:`MAX_CHANNELS`, PCM 8/16/24/32-bit or float 32/64-bit. A claimed data
    size above :data:`MAX_DURATION_S` (``arecord`` writes a huge one for an open-ended recording) counts as
    unknown: the stream is read to its end, at most :data:`MAX_DURATION_S`.

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> from skeleton_mamba.tasks.motion.synthetic.music import write_tone
        >>> path = write_tone(Path(tempfile.mkdtemp()) / "tone.wav")  # 0.5 s of 440 Hz, 16 kHz mono PCM
        >>> import io
        >>> import numpy as np
        >>> with open_wav_stream(io.BytesIO(path.read_bytes()), name="pipe") as reader:
        ...     samples = np.concatenate(list(reader.blocks()))
        >>> reader.info.name, samples.shape
        ('pipe', (8000, 1))
    """
    layout = _parse_wav_header(stream, name, "stream")
    if isinstance(layout, int):
        raise AudioFileError(f"{name}: WAV format tag {layout:#06x}; a stream must be PCM or float WAV")
    claimed = layout.claimed
    if claimed is not None and claimed // layout.block_align / layout.rate > MAX_DURATION_S:
        claimed = None
    info = AudioInfo(name, layout.rate, layout.channels, None, layout.encoding)
    return AudioReader(info, stream, layout, limit_bytes=claimed)


def _open_wav_file(path: Path) -> AudioReader | None:
    """The reader of a PCM/float WAV file, or ``None`` when libsndfile should decode it (another encoding)."""
    name = str(path)
    stream = open(path, "rb")  # noqa: SIM115 (the reader closes it)
    try:
        layout = _parse_wav_header(stream, name)
        if isinstance(layout, int):
            stream.close()
            return None
        size = os.fstat(stream.fileno()).st_size
        available = max(0, size - layout.data_offset)
        align = layout.block_align
        if layout.claimed is None:
            usable = available
        elif layout.claimed > available:
            usable = available
            warnings.warn(
                f"{name}: the WAV header claims {layout.claimed} data bytes "
                f"({_clock(layout.claimed // align / layout.rate)}), the file holds {available} after byte "
                f"{layout.data_offset}; reading those ({_clock(available // align / layout.rate)})",
                AudioWarning,
                stacklevel=3,
            )
        else:
            usable = layout.claimed
            end = layout.data_offset + usable + (usable & 1)
            if end < size and not _trailing_is_chunks(stream, end, size):
                warnings.warn(
                    f"{name}: the WAV header claims {usable} data bytes "
                    f"({_clock(usable // align / layout.rate)}) "
                    f"but {size - end} bytes after byte {end} are no RIFF chunk; read only the claimed data",
                    AudioWarning,
                    stacklevel=3,
                )
        if usable % align:
            warnings.warn(
                f"{name}: the data ends inside a frame at byte {layout.data_offset + usable}; "
                f"the last {usable % align} bytes are ignored",
                AudioWarning,
                stacklevel=3,
            )
        frames = usable // align
        check_format(name, layout.rate, layout.channels, frames)
        stream.seek(layout.data_offset)
        info = AudioInfo(name, layout.rate, layout.channels, frames, layout.encoding)
        return AudioReader(info, stream, layout)
    except BaseException:
        stream.close()
        raise


def _reason(err: BaseException) -> str:
    text = str(err).strip()
    if isinstance(err, soundfile.LibsndfileError):
        text = err.error_string or text
    return text or f"{type(err).__name__}, no reason given"


def open_audio(path: str | os.PathLike) -> AudioReader:
    """An :class:`AudioReader` of the audio file ``path`` after the header checks (see the module docstring).

    Raises:
        FileNotFoundError: ``path`` is not a file.
        AudioFileError: the header is malformed or out of bounds, or the format is not one libsndfile reads.

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> from skeleton_mamba.tasks.motion.synthetic.music import write_tone
        >>> path = write_tone(Path(tempfile.mkdtemp()) / "tone.wav")  # 0.5 s of 440 Hz, 16 kHz mono PCM
        >>> with open_audio(path) as reader:
        ...     blocks = list(reader.blocks(block_frames=3000))
        >>> reader.info.sample_rate, [block.shape for block in blocks]
        (16000, [(3000, 1), (3000, 1), (2000, 1)])
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: audio file not found")
    with open(path, "rb") as f:
        is_wav = f.read(12)[8:12] == b"WAVE"
    if is_wav and (reader := _open_wav_file(path)) is not None:
        return reader
    try:
        sound = soundfile.SoundFile(path)
    except Exception as err:  # libsndfile raises LibsndfileError, RuntimeError or TypeError
        raise AudioFileError(
            f"{path}: cannot decode audio ({_reason(err)}); readable: WAV, FLAC, Ogg Vorbis/Opus, MP3 and "
            "the other formats of libsndfile"
        ) from err
    try:
        check_format(str(path), sound.samplerate, sound.channels, max(0, sound.frames))
    except BaseException:
        sound.close()
        raise
    frames = max(0, sound.frames)
    info = AudioInfo(str(path), int(sound.samplerate), int(sound.channels), frames, str(sound.subtype))
    return AudioReader(info, sound=sound)


def probe_audio(path: str | os.PathLike) -> AudioInfo:
    """The checked header of ``path`` (:func:`open_audio` without decoding a sample).

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> from skeleton_mamba.tasks.motion.synthetic.music import write_tone
        >>> path = write_tone(Path(tempfile.mkdtemp()) / "tone.wav")  # 0.5 s of 440 Hz, 16 kHz mono PCM
        >>> info = probe_audio(path)
        >>> info.sample_rate, info.channels, info.frames, info.encoding, info.duration_s
        (16000, 1, 8000, 'PCM 16-bit', 0.5)
    """
    with open_audio(path) as reader:
        return reader.info


def read_audio(
    path: str | os.PathLike, offset_s: float = 0.0, duration_s: float | None = None, mono: bool = True
) -> tuple[np.ndarray, int]:
    """Decode ``path`` (or ``duration_s`` seconds from ``offset_s``) as float32 at its own rate.

    Returns:
        ``(samples, sample_rate)``: ``(N,)`` with ``mono`` (the mean of the channels, as librosa mixes),
        else ``(N, channels)``.

    Raises:
        FileNotFoundError: no such file.
        AudioFileError: a refused header, a decode error, bad samples, or no samples at all.

    Examples:
        >>> import tempfile
        >>> from pathlib import Path
        >>> from skeleton_mamba.tasks.motion.synthetic.music import write_tone
        >>> path = write_tone(Path(tempfile.mkdtemp()) / "tone.wav")  # 0.5 s of 440 Hz, 16 kHz mono PCM
        >>> samples, rate = read_audio(path, offset_s=0.25)
        >>> samples.shape, samples.dtype, rate, round(float(abs(samples).max()), 2)
        ((4000,), dtype('float32'), 16000, 0.5)
    """
    with open_audio(path) as reader:
        info = reader.info
        start = max(0, int(round(offset_s * info.sample_rate)))
        count = max(0, info.frames - start)
        if duration_s is not None:
            count = min(count, max(0, int(round(duration_s * info.sample_rate))))
        out = np.empty((count,) if mono else (count, info.channels), dtype=np.float32)
        filled = 0
        for block in reader.blocks(start, count):
            n = min(len(block), count - filled)
            out[filled : filled + n] = block[:n].mean(axis=1) if mono else block[:n]
            filled += n
    if filled == 0:
        where = "" if start == 0 and duration_s is None else f" from {_clock(start / info.sample_rate)}"
        raise AudioFileError(f"{path}: the audio holds no samples{where}")
    return out[:filled], info.sample_rate
