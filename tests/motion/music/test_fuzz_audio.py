"""Hostile audio (issue 33): the one reader refuses bad headers and samples on one line, in bounded memory.

WAV files are generated here byte by byte (:func:`_wav`): absurd rates (0, 1 Hz, 4294967295 Hz), 1000
channels, float samples of 1e38 or NaN, data chunks claiming more or less than the file holds, truncation,
a 10-hour WAV written with a seek so that it stays small on disk, and random corruptions of WAV, FLAC and
Ogg files. Every refusal must be an :class:`AudioFileError` naming the file; ``sm analyze-music`` and
``sm render --music`` must exit 2 with one line, no traceback, nothing written (an old mp4 keeps its
bytes), and a few of them run under an address-space limit (``RLIMIT_AS``, as in ``test_fuzz_hostile.py``)
so that an allocation scaled by a hostile header fails the test. Accepted audio (PCM 8/16/24/32-bit, float
32/64-bit, stereo, extensible headers, on standard input too) is compared with the integers it was written
from and with libsndfile's decoding.
"""

from __future__ import annotations

import io
import resource
import struct
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skeleton_mamba.tasks.motion.formats.mp4 import Mp4WriteError, write_mp4
from skeleton_mamba.tasks.motion.music import audio_io
from skeleton_mamba.tasks.motion.music.audio_io import AudioFileError, AudioWarning, read_audio
from skeleton_mamba.tasks.stream.audio_input import AudioSource
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.sm import sm_executable

MEMORY_LIMIT = 3 << 30  # bytes of address space for an `sm` subprocess
RATE = 22050
FUZZ = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def _wav(
    data: bytes, rate=RATE, channels=1, bits=16, tag=1, claim=None, align=None, extensible=False
) -> bytes:
    """A RIFF/WAVE file: ``fmt `` (optionally WAVE_FORMAT_EXTENSIBLE), then ``data`` claiming ``claim``."""
    align = channels * bits // 8 if align is None else align
    fmt = struct.pack("<HHIIHH", 0xFFFE if extensible else tag, channels, rate, (rate * align) & 0xFFFFFFFF,
                      align, bits)  # fmt: skip
    if extensible:  # cbSize 22, valid bits, channel mask, sub-format GUID (tag + the KSDATAFORMAT tail)
        fmt += (
            struct.pack("<HHI", 22, bits, 0)
            + struct.pack("<H", tag)
            + bytes.fromhex("000000001000800000aa00389b71")
        )
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt
    body += b"data" + struct.pack("<I", len(data) if claim is None else claim) + data
    return b"RIFF" + struct.pack("<I", len(body) & 0xFFFFFFFF) + body


def _tone(n=RATE // 2, channels=1) -> np.ndarray:
    t = np.arange(n)[:, None] / RATE
    return 0.5 * np.sin(2 * np.pi * 440.0 * t * (1 + np.arange(channels)))  # (n, channels) float64


def _pcm16(x: np.ndarray) -> bytes:
    return np.round(x * 32767).astype("<i2").tobytes()


def _ten_hours(path: Path) -> None:
    """A 10-hour 16-bit mono WAV at 44.1 kHz, sparse: the header, then a seek to the end (3.2 GB apparent)."""
    size = 10 * 3600 * 44100 * 2
    with open(path, "wb") as f:
        f.write(_wav(b"", rate=44100, claim=size))
        f.seek(size - 1, 1)
        f.write(b"\0")


# name -> (bytes or a writer, text the one-line error holds)
HOSTILE = {
    "rate_0": (_wav(_pcm16(_tone()), rate=0), "sample rate 0 Hz is outside 8000-192000 Hz"),
    "rate_1_hz": (_wav(_pcm16(_tone()), rate=1), "sample rate 1 Hz is outside"),
    "rate_4294967295": (_wav(_pcm16(_tone()), rate=4294967295), "sample rate 4.29497e+09 Hz is outside"),
    "channels_1000": (_wav(bytes(2000 * 64), channels=1000), "1000 channels, audio has 1 to 8"),
    "float_1e38": (_wav(np.full(4096, 1e38, "<f4").tobytes(), bits=32, tag=3),
                   "samples out of range, the first (1e+38)"),
    "float64_1e300": (_wav(np.full(64, 1e300, "<f8").tobytes(), bits=64, tag=3), "samples out of range"),
    "float_nan": (_wav(np.r_[_tone(1000)[:, 0], np.nan].astype("<f4").tobytes(), bits=32, tag=3),
                  "audio samples are NaN or Inf, the first (nan) at 0.045 s, byte 4044"),
    "ten_hours_sparse": (_ten_hours, "10.00 hours of audio, more than the 1 hour"),
    "no_samples": (_wav(b""), "the audio holds no samples"),
    "not_audio": (b"this is not audio at all", "cannot decode audio"),
    "header_only": (_wav(b"")[:30], "claims 16 bytes, the file ends 10 bytes later"),
    "chunk_bomb": (b"RIFF\xff\xff\xff\xffWAVEjunk\xff\xff\xff\x7f", "at most 1048576 bytes of chunks"),
    "frame_size_lies": (_wav(_pcm16(_tone()), align=7), "says 7 bytes per frame"),
    "pcm_12_bit": (_wav(_pcm16(_tone()), bits=12, align=2), "12-bit PCM WAV"),
    "float_16_bit": (_wav(_pcm16(_tone()), bits=16, tag=3), "16-bit float WAV"),
    "big_endian": (b"RIFX" + _wav(_pcm16(_tone()))[4:], "big-endian RIFX"),
}  # fmt: skip


def _write_case(folder: Path, case: str) -> tuple[Path, str]:
    content, expected = HOSTILE[case]
    path = folder / f"{case}.wav"
    content(path) if callable(content) else path.write_bytes(content)
    return path, expected


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_the_reader_refuses_hostile_audio_naming_the_file(tmp_path, case):
    path, expected = _write_case(tmp_path, case)
    with pytest.raises(AudioFileError) as info:
        read_audio(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and expected in message and "\n" not in message


def _motion(folder: Path) -> Path:
    from skeleton_mamba.tasks.motion.formats.motion_file import save_motion
    from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance

    return save_motion(folder / "m.npz", synthesize_dance(120, 1.0, 10.0, "bounce", 1))


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_sm_analyze_music_and_render_refuse_on_one_line_and_write_nothing(tmp_path, case, capsys):
    path, expected = _write_case(tmp_path, case)
    motion = _motion(tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    old = work / "old.mp4"
    old.write_bytes(b"an earlier rendering")
    assert sm_main(["analyze-music", str(path), "--no-cache", "--out", str(work / "f.npy")]) == 2
    assert sm_main(["render", str(motion), "--music", str(path), "--out", str(old), "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 2 and "Traceback" not in "".join(lines), lines
    assert lines[0].startswith(f"sm analyze-music: error: {path}: ") and expected in lines[0]
    assert lines[1].startswith(f"sm render: error: {path}: ") and expected in lines[1]
    assert sorted(p.name for p in work.iterdir()) == ["old.mp4"]  # no features, no temporary file
    assert old.read_bytes() == b"an earlier rendering"


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


@pytest.mark.parametrize(
    ("command", "case"),
    [("analyze-music", "ten_hours_sparse"), ("analyze-music", "rate_4294967295"),
     ("render", "ten_hours_sparse"), ("render", "float_1e38")],
)  # fmt: skip
def test_sm_refuses_hostile_audio_in_bounded_memory(tmp_path, command, case):
    """The real command under a 3 GB address-space limit (before the fix: past 4 GB, or a traceback)."""
    path, expected = _write_case(tmp_path, case)
    work = tmp_path / "work"
    work.mkdir()
    if command == "render":
        args = [
            "render",
            str(_motion(tmp_path)),
            "--music",
            str(path),
            "--out",
            str(work / "v.mp4"),
            "--quiet",
        ]
    else:
        args = ["analyze-music", str(path), "--no-cache"]
    proc = subprocess.run([sm_executable(), *args], cwd=work, capture_output=True, text=True, timeout=300,
                          preexec_fn=_limit_memory)  # fmt: skip
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert str(path) in lines[0] and expected in lines[0]
    assert list(work.iterdir()) == []


# ----------------------------------------------------------------------------- accepted audio


def _integers(bits: int, n: int, channels: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    low, high = (0, 256) if bits == 8 else (-(1 << (bits - 1)), 1 << (bits - 1))
    return rng.integers(low, high, size=(n, channels), dtype=np.int64)


def _pcm_bytes(values: np.ndarray, bits: int) -> bytes:
    if bits == 8:
        return values.astype(np.uint8).tobytes()
    if bits == 24:
        return b"".join(int(v).to_bytes(3, "little", signed=True) for v in values.ravel())
    return values.astype(f"<i{bits // 8}").tobytes()


def _full_scale(values: np.ndarray, bits: int) -> np.ndarray:
    """The hand-written rule: unsigned 8-bit is offset by 128; signed widths divide by 2^(bits-1)."""
    return (values - 128) / 128.0 if bits == 8 else values / float(1 << (bits - 1))


@pytest.mark.parametrize("extensible", [False, True], ids=["plain", "extensible"])
@pytest.mark.parametrize("channels", [1, 2, 8])
@pytest.mark.parametrize("bits", [8, 16, 24, 32])
def test_pcm_widths_decode_to_the_written_integers_and_match_libsndfile(tmp_path, bits, channels, extensible):
    values = _integers(bits, 300, channels, seed=bits + channels)
    path = tmp_path / "a.wav"
    path.write_bytes(_wav(_pcm_bytes(values, bits), channels=channels, bits=bits, extensible=extensible))
    y, rate = read_audio(path, mono=False)
    assert rate == RATE and y.dtype == np.float32 and y.shape == (300, channels)
    np.testing.assert_allclose(y, _full_scale(values, bits), rtol=0, atol=1e-7)
    reference, _ = sf.read(path, dtype="float64", always_2d=True)  # libsndfile, an independent decoder
    np.testing.assert_allclose(y, reference, rtol=0, atol=1e-7)
    mono, _ = read_audio(path)
    np.testing.assert_allclose(mono, _full_scale(values, bits).mean(axis=1), rtol=0, atol=1e-6)


@pytest.mark.parametrize("bits", [32, 64])
def test_float_wav_within_headroom_is_read_as_written(tmp_path, bits):
    x = np.r_[_tone(200)[:, 0], 1.5, -7.9]  # a little above full scale is ordinary float audio
    path = tmp_path / "f.wav"
    path.write_bytes(_wav(x.astype(f"<f{bits // 8}").tobytes(), bits=bits, tag=3))
    y, _ = read_audio(path)
    np.testing.assert_array_equal(y, x.astype(np.float32))


def test_header_claiming_more_or_less_data_reads_the_usable_part_with_a_warning(tmp_path):
    values = _integers(16, 1000, 1, seed=3)
    data = _pcm_bytes(values, 16)
    cases = {
        "more": (_wav(data, claim=10**6), 1000, "claims 1000000 data bytes"),
        "less": (_wav(data, claim=400), 200, "claims 400 data bytes"),
        "cut": (_wav(data)[: 44 + 1201], 600, "the file holds 1201 after byte 44"),
    }
    for name, (content, frames, expected) in cases.items():
        path = tmp_path / f"{name}.wav"
        path.write_bytes(content)
        with pytest.warns(AudioWarning, match=expected) as record:
            y, _ = read_audio(path)
        assert all(str(path) in str(w.message) for w in record)
        np.testing.assert_array_equal(y, (values[:frames, 0] / 32768.0).astype(np.float32))


def test_a_riff_chunk_after_the_data_is_no_mismatch(tmp_path):
    data = _pcm_bytes(_integers(16, 100, 1, seed=4), 16)
    tail = b"LIST" + struct.pack("<I", 4) + b"INFO"
    body = _wav(data) + tail
    path = tmp_path / "list.wav"
    path.write_bytes(body[:4] + struct.pack("<I", len(body) - 8) + body[8:])
    with warnings.catch_warnings():
        warnings.simplefilter("error", AudioWarning)
        assert read_audio(path)[0].shape == (100,)


def test_a_slice_is_read_without_the_rest(tmp_path):
    values = _integers(16, RATE, 2, seed=5)
    path = tmp_path / "s.wav"
    path.write_bytes(_wav(_pcm_bytes(values, 16), channels=2))
    y, _ = read_audio(path, offset_s=0.25, duration_s=0.5)
    start, count = RATE // 4, RATE // 2
    np.testing.assert_allclose(y, values[start : start + count].mean(axis=1) / 32768.0, rtol=0, atol=1e-7)


@pytest.mark.parametrize(
    ("bits", "channels", "tag"),
    [(8, 1, 1), (16, 2, 1), (24, 2, 1), (32, 1, 3)],
    ids=["8bit", "stereo", "24bit", "float"],
)
def test_standard_input_takes_ordinary_wav_streams(monkeypatch, bits, channels, tag):
    if tag == 3:
        written = _tone(500, channels)
        data, expected = written.astype("<f4").tobytes(), written.astype(np.float32)
    else:
        values = _integers(bits, 500, channels, seed=bits)
        data, expected = _pcm_bytes(values, bits), _full_scale(values, bits)
    monkeypatch.setattr(
        sys, "stdin", io.TextIOWrapper(io.BytesIO(_wav(data, channels=channels, bits=bits, tag=tag)))
    )
    source = AudioSource("-", chunk_s=0.002)
    assert (source.sample_rate, source.channels) == (RATE, channels)
    with warnings.catch_warnings():
        warnings.simplefilter("error", AudioWarning)  # the stream ends where its header says
        got = np.concatenate([c.samples for c in source])
    np.testing.assert_allclose(got, expected.mean(axis=1), rtol=0, atol=1e-6)


@pytest.mark.parametrize("case", ["rate_0", "rate_4294967295", "channels_1000", "pcm_12_bit", "not_audio"])
def test_standard_input_refuses_hostile_headers(monkeypatch, case):
    content, expected = HOSTILE[case]
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(content)))
    with pytest.raises(AudioFileError, match="^standard input: ") as info:
        AudioSource("-")
    assert (expected if case != "not_audio" else "not a WAV stream") in str(info.value)


def test_standard_input_stops_at_bad_samples_and_reports_a_cut_stream(monkeypatch):
    content, _ = HOSTILE["float_nan"]
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(content)))
    with pytest.raises(
        AudioFileError, match=r"standard input: audio samples are NaN or Inf, the first \(nan\)"
    ):
        list(AudioSource("-"))
    values = _integers(16, 1000, 1, seed=6)
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(_wav(_pcm_bytes(values, 16))[:-500])))
    with pytest.warns(AudioWarning, match="standard input: ends at byte 1544, 0.034 s of the 0.045 s"):
        got = np.concatenate([c.samples for c in AudioSource("-")])
    np.testing.assert_array_equal(got, (values[:750, 0] / 32768.0).astype(np.float32))


def test_undecodable_formats_say_why_not_an_empty_backend_error(tmp_path):
    path = tmp_path / "song.m4a"
    path.write_bytes(b"\0\0\0\x20ftypM4A " + bytes(64))
    with pytest.raises(AudioFileError, match=r"song.m4a: cannot decode audio \(.+\); readable: WAV, FLAC"):
        read_audio(path)


# ----------------------------------------------------------------------------- random corruption


def _valid_files() -> dict[str, bytes]:
    y = _tone(RATE // 4, 2).astype(np.float32)
    files = {"wav": _wav(_pcm16(y), channels=2)}
    for kind, fmt in (("flac", "FLAC"), ("ogg", "OGG")):
        buffer = io.BytesIO()
        sf.write(buffer, y, RATE, format=fmt)
        files[kind] = buffer.getvalue()
    return files


VALID = _valid_files()


@FUZZ
@given(data=st.data())
def test_corrupted_files_decode_to_bounded_finite_audio_or_refuse(data):
    kind = data.draw(st.sampled_from(sorted(VALID)))
    content = bytearray(VALID[kind])
    for _ in range(data.draw(st.integers(1, 4))):
        action = data.draw(st.sampled_from(["flip", "flip", "truncate", "zero", "poison"]))
        i = data.draw(st.integers(0, len(content) - 1))
        if action == "flip":
            content[i] ^= 1 << data.draw(st.integers(0, 7))
        elif action == "truncate":
            del content[i:]
        elif action == "zero":
            content[i : i + 64] = bytes(len(content[i : i + 64]))
        else:  # a 32-bit field (a size, a rate) set to an extreme
            content[i : i + 4] = data.draw(
                st.sampled_from([b"\xff\xff\xff\xff", b"\0\0\0\0", b"\xff\xff\xff\x7f"])
            )
        if not content:
            content = bytearray(b"\0")
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"x.{kind}"
        path.write_bytes(bytes(content))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", AudioWarning)
                y, rate = read_audio(path, mono=False)
        except AudioFileError as err:
            assert str(err).startswith(f"{path}: ") and "\n" not in str(err)
            return
    assert audio_io.MIN_SAMPLE_RATE <= rate <= audio_io.MAX_SAMPLE_RATE
    assert 1 <= y.shape[1] <= audio_io.MAX_CHANNELS and y.dtype == np.float32
    assert np.all(np.abs(y) <= audio_io.MAX_ABS_SAMPLE)


# ----------------------------------------------------------------------------- mp4 writer


def test_ffmpeg_failures_are_one_line_errors_naming_the_target(tmp_path):
    frames = [np.zeros((64, 64, 3), np.uint8)] * 30
    bad = tmp_path / "bad.wav"
    bad.write_bytes(b"RIFF but no audio")
    target = tmp_path / "clip.mp4"
    with pytest.raises(Mp4WriteError) as info:  # ffmpeg exits at once: the pipe breaks or it fails
        write_mp4(tmp_path / ".clip.tmp.mp4", frames, (64, 64), 30.0, audio_wav=bad, target=target)
    assert info.value.filename == str(target) and "ffmpeg" in info.value.strerror
    assert "\n" not in info.value.strerror
    with pytest.raises(Mp4WriteError, match="no frames to encode|ffmpeg"):
        write_mp4(tmp_path / "none.mp4", [], (64, 64), 30.0)


def test_an_mp4_with_music_has_its_sound_stream(tmp_path):
    from skeleton_mamba.tasks.motion.formats.mp4 import _has_stream

    wav = tmp_path / "m.wav"
    sf.write(wav, _tone(RATE).astype(np.float32), RATE)
    out = tmp_path / "v.mp4"
    assert write_mp4(out, [np.full((64, 64, 3), 90, np.uint8)] * 20, (64, 64), 20.0, audio_wav=wav) == 20
    assert _has_stream(out, "v") and _has_stream(out, "a")
