"""Hostile motion, video and Kinetics files (issue 33): refused on one line, within bounded memory.

Each class of hostile input is built here by hand (pickle opcodes, zip members, PNG headers, JSON text) and
read by the project's readers, which must raise the project's error types with one line naming the file;
the classes that would allocate gigabytes are also run through ``sm render`` / ``sm export`` under an
address-space limit (``RLIMIT_AS``), where a bound that let them through would fail by running out of
memory. The video reader's peak memory is measured for a short and a ten-times longer video.
"""

from __future__ import annotations

import ast
import io
import json
import pickle
import resource
import struct
import subprocess
import sys
import textwrap
import zipfile
import zlib
from pathlib import Path

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np
import pytest
import torch

from skeleton_mamba.errors import SkeletonMambaError
from skeleton_mamba.tasks.egodance.frames import (
    MAX_IMAGE_PIXELS,
    iter_video_frames,
    read_image,
    read_video_frames,
    resize_frames,
)
from skeleton_mamba.tasks.motion.formats.aistpp import load_aistpp_motion
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, load_motion, save_motion
from skeleton_mamba.tasks.motion.io.safe_pickle import MAX_PICKLE_OBJECT_BYTES, safe_loads_pickle
from skeleton_mamba.tasks.motion.io.value_checks import MAX_NPZ_MEMBER_BYTES, load_npz
from skeleton_mamba.tasks.recognition.kinetics import read_kinetics_clip, read_kinetics_labels
from tests.helpers.peak_memory import PEAK_KIB_SOURCE
from tests.helpers.sm import sm_executable

MEMORY_LIMIT = 3 << 30  # bytes of address space for the `sm` subprocess (each bomb claims 6 GB or more)
AIST_NAME = "gBR_sBM_cAll_d04_mBR0_ch01.pkl"


def _global(module: str, name: str) -> bytes:
    return b"c" + module.encode() + b"\n" + name.encode() + b"\n"  # GLOBAL, protocol 0 text form


def _binint(n: int) -> bytes:
    return b"\x8a" + bytes([(n.bit_length() + 8) // 8]) + n.to_bytes((n.bit_length() + 8) // 8, "little")


def _unicode(text: str) -> bytes:
    raw = text.encode()
    return b"X" + struct.pack("<I", len(raw)) + raw  # BINUNICODE


def _dict_of(key: str, value_ops: bytes) -> bytes:
    """A protocol-2 pickle of ``{key: <value>}`` where ``value_ops`` pushes the value."""
    return b"\x80\x02}" + _unicode(key) + value_ops + b"s."


# name -> (pickle bytes, what the one-line message says)
CLAIM_6GB = struct.pack("<Q", 6_000_000_000)
SAYS_6GB = "claims 6000000000 bytes"
HOSTILE_PICKLES = {
    "bytes8_6GB": (b"\x80\x04\x8e" + CLAIM_6GB + b"abc.", SAYS_6GB),
    "bytearray8_6GB": (b"\x80\x05\x96" + CLAIM_6GB + b"abc.", SAYS_6GB),
    "unicode8_6GB": (b"\x80\x04\x8d" + CLAIM_6GB + b"abc.", SAYS_6GB),
    "frame_6GB": (b"\x80\x04\x95" + CLAIM_6GB + b"}.", SAYS_6GB),
    "bytes_call_6GB": (_global("builtins", "bytes") + _binint(6 * 10**9) + b"\x85R.", "bytes(6000000000)"),
    "list_of_1e9": (
        _global("builtins", "list") + _global("builtins", "range") + _binint(10**9) + b"\x85R\x85R.",
        "list() of 1000000000 items",
    ),
    "ndarray_728TB": (
        _dict_of("smpl_poses", _global("numpy", "ndarray") + _binint(91 * 10**12) + b"\x85\x85R"),
        "claims 728000000000000 bytes",
    ),
    "object_dtype": (
        _global("numpy", "dtype") + _unicode("O8") + b"\x89\x88\x87R.",
        "arrays of Python objects",
    ),
    "unknown_codec": (
        _global("_codecs", "encode") + _unicode("abc") + _unicode("no-such-codec") + b"\x86R.",
        "codec 'no-such-codec' is not admitted",
    ),
    "reconstruct_subtype": (
        _global("numpy.core.multiarray", "_reconstruct")
        + _global("builtins", "list")
        + b"K\x00\x85C\x01b\x87R.",
        "only plain numpy arrays",
    ),
    "truncated_claim": (b"\x80\x04\x8e" + struct.pack("<Q", 1000) + b"abc.", "pickle data was truncated"),
    "os_system": (_global("os", "system") + _unicode("true") + b"\x85R.", "refusing to unpickle global"),
}  # fmt: skip


def _one_line(err: BaseException, path: Path | str) -> str:
    message = str(err)
    assert "\n" not in message and str(path) in message, message
    return message


@pytest.mark.parametrize("case", sorted(HOSTILE_PICKLES))
def test_hostile_pickles_are_refused_before_allocating(case):
    data, expected = HOSTILE_PICKLES[case]
    with pytest.raises(SkeletonMambaError) as info:
        safe_loads_pickle(data, f"{case}.pkl")
    assert expected in _one_line(info.value, f"{case}.pkl")


def test_pickle_bounds_admit_real_data_in_every_protocol():
    value = {"a": np.arange(12, dtype=np.float32).reshape(3, 4), "b": [1, 2.5, "x", b"yz"], "c": {3, 4}}
    value["d"] = bytearray(b"\x00\x01")
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        loaded = safe_loads_pickle(pickle.dumps(value, protocol=protocol))
        np.testing.assert_array_equal(loaded["a"], value["a"])
        assert loaded["b"] == value["b"] and loaded["c"] == value["c"] and loaded["d"] == value["d"]


def test_pickle_object_bound_is_exact(monkeypatch):
    from skeleton_mamba.tasks.motion.io import safe_pickle

    monkeypatch.setattr(safe_pickle, "MAX_PICKLE_OBJECT_BYTES", 16)
    assert safe_loads_pickle(pickle.dumps(b"x" * 16, protocol=3)) == b"x" * 16  # protocol 3: no frames
    with pytest.raises(SkeletonMambaError, match="claims 17 bytes, more than the 16"):
        safe_loads_pickle(pickle.dumps(b"x" * 17, protocol=3))
    assert MAX_PICKLE_OBJECT_BYTES == 1 << 30


def _aist(poses, trans=None, scaling=None) -> dict:
    n = len(poses) if hasattr(poses, "__len__") else 4
    return {
        "smpl_poses": poses,
        "smpl_trans": np.zeros((n, 3)) if trans is None else trans,
        "smpl_scaling": np.array([1.0]) if scaling is None else scaling,
    }


HOSTILE_AIST = {
    "complex_poses": (_aist(np.zeros((4, 72), np.complex64)), "'smpl_poses' must hold real numbers"),
    "datetime_poses": (_aist(np.zeros((4, 72), "datetime64[s]")), "real numbers, got dtype datetime64"),
    "string_poses": (_aist(np.full((4, 72), "1.0")), "must hold real numbers"),
    "timedelta_trans": (_aist(np.zeros((4, 72)), np.zeros((4, 3), "m8[s]")), "'smpl_trans' must hold real"),
    "far_trans": (_aist(np.zeros((4, 72)), np.full((4, 3), 1e9)), "root position"),
    "huge_rotation": (_aist(np.full((4, 72), 1e7)), "smpl_poses: 1e+07 rad at frame 0"),
    "tiny_scaling": (_aist(np.zeros((4, 72)), None, np.array([1e-30])), "smpl_scaling must be a number"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(HOSTILE_AIST))
def test_aistpp_pickles_with_non_real_or_implausible_values_are_refused(tmp_path, case):
    data, expected = HOSTILE_AIST[case]
    path = tmp_path / AIST_NAME
    path.write_bytes(pickle.dumps(data, protocol=4))
    with pytest.raises(SkeletonMambaError) as info:
        load_aistpp_motion(path)
    assert expected in _one_line(info.value, path)


def _npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=True)
    return buffer.getvalue()


def _zip(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, raw in members.items():
            archive.writestr(name, raw)
    return path


def _zip_bomb(path: Path, claimed_rows: int = 725_000_000, zeros: int = 64 << 20) -> Path:
    """An .npz whose 'joints' header claims (rows, 2) float32 (5.8 GB) over a stream of zeros."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f4", "fortran_order": False, "shape": (claimed_rows, 2)}
    )
    return _zip(path, {"fps.npy": _npy_bytes(np.array(30.0)), "joints.npy": header.getvalue() + bytes(zeros)})


def _motion_members(**override) -> dict[str, bytes]:
    arrays = {"fps": np.array(30.0), "skeleton": np.array("smpl24"), "joints": np.zeros((4, 24, 3))}
    arrays.update(override)
    return {f"{k}.npy": _npy_bytes(v) for k, v in arrays.items()}


def _lying_member(path: Path) -> Path:
    """A 'joints' member whose header says (4, 24, 3) float64 but which inflates 64 MB more."""
    raw = _npy_bytes(np.zeros((4, 24, 3)))
    return _zip(path, {**_motion_members(), "joints.npy": raw + bytes(64 << 20)})


CUT_JOINTS = _npy_bytes(np.zeros((4, 24, 3)))[:200]
HOSTILE_NPZ = {
    "zip_bomb_5.8GB": (_zip_bomb, "claims (725000000, 2) float32 (5800000000 bytes)"),
    "lying_member": (_lying_member, "more data than its header says"),
    "complex_joints": (lambda p: _zip(p, _motion_members(joints=np.zeros((4, 24, 3), np.complex128))),
                       "'joints' must hold real numbers, got dtype complex128"),
    "datetime_fps": (lambda p: _zip(p, _motion_members(fps=np.array(1, "datetime64[s]"))),
                     "'fps' must hold real numbers"),
    "object_joints": (lambda p: _zip(p, _motion_members(joints=np.array([None, 1], dtype=object))),
                      "must hold real numbers, got dtype object"),
    "structured_joints": (lambda p: _zip(p, _motion_members(joints=np.zeros(3, "f4,f4"))),
                          "must hold real numbers"),
    "far_joints": (lambda p: _zip(p, _motion_members(joints=np.full((4, 24, 3), 2e6))),
                   "joints: 2e+06 m at frame 0, joint 0, axis 0"),
    "long_skeleton_name": (lambda p: _zip(p, _motion_members(skeleton=np.array("s" * 1000))),
                           "'skeleton' must be one name"),
    "truncated_member": (lambda p: _zip(p, {**_motion_members(), "joints.npy": CUT_JOINTS}), "truncated"),
    "not_a_zip": (lambda p: (p.write_bytes(b"PK\x03\x04" + bytes(100)), p)[1], "not a readable .npz"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(HOSTILE_NPZ))
def test_hostile_motion_npz_is_refused_on_one_line(tmp_path, case):
    build, expected = HOSTILE_NPZ[case]
    path = build(tmp_path / "motion.npz")
    with pytest.raises(SkeletonMambaError) as info:
        load_motion(path)
    assert expected in _one_line(info.value, path)


def test_npz_member_bound_is_exact(tmp_path):
    path = _zip(tmp_path / "a.npz", {"x.npy": _npy_bytes(np.zeros(4, np.float32))})  # 16 bytes
    np.testing.assert_array_equal(load_npz(path, max_member_bytes=16)["x"], np.zeros(4))
    with pytest.raises(SkeletonMambaError, match=r"claims \(4,\) float32 \(16 bytes\), more than the 15"):
        load_npz(path, max_member_bytes=15)
    assert MAX_NPZ_MEMBER_BYTES == 1 << 30


def test_bounded_npz_reads_what_numpy_writes(tmp_path):
    rng = np.random.default_rng(0)
    motion = MotionData(30.0, "smpl24", poses=rng.normal(size=(5, 24, 3)), trans=rng.normal(size=(5, 3)))
    save_motion(tmp_path / "m.npz", motion)
    with np.load(tmp_path / "m.npz") as data:  # numpy's own reader as the reference
        expected = {k: data[k] for k in data.files}
    got = load_npz(tmp_path / "m.npz", text_keys=("skeleton",))
    assert sorted(got) == sorted(expected)
    for key in expected:
        np.testing.assert_array_equal(got[key], expected[key])
    fortran = np.asfortranarray(rng.normal(size=(3, 4)))
    np.savez(tmp_path / "f.npz", a=fortran)
    np.testing.assert_array_equal(load_npz(tmp_path / "f.npz")["a"], fortran)


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _run_sm(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sm_executable(), *args], cwd=cwd, capture_output=True, text=True, timeout=300,
                          preexec_fn=_limit_memory)  # fmt: skip


SM_CASES = ["bytes8_6GB", "list_of_1e9", "ndarray_728TB", "unknown_codec", "zip_bomb_5.8GB", "complex_joints"]


@pytest.mark.parametrize("command", ["render", "export"])
@pytest.mark.parametrize("case", SM_CASES)
def test_sm_refuses_hostile_motion_files_in_bounded_memory(tmp_path, case, command):
    inputs = tmp_path / "in"
    inputs.mkdir()
    if case in HOSTILE_PICKLES:
        path = inputs / AIST_NAME
        path.write_bytes(HOSTILE_PICKLES[case][0])
    else:
        path = HOSTILE_NPZ[case][0](inputs / "motion.npz")
    work = tmp_path / "work"
    work.mkdir()
    out = work / ("out.mp4" if command == "render" else "out.glb")
    proc = _run_sm([command, str(path), "--out", str(out)], work)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert str(path) in lines[0]
    assert list(work.iterdir()) == []  # nothing written


# ---------------------------------------------------------------------------------------------- images


def _png_header(width: int, height: int) -> bytes:
    """A PNG whose IHDR claims width x height RGB and whose image data is a few bytes (never decoded)."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\0" * 64))
        + chunk(b"IEND", b"")
    )


@pytest.mark.parametrize(("width", "height"), [(20000, 20000), (8000, 6000)], ids=["400MP", "48MP"])
def test_oversized_images_are_refused_from_the_header(tmp_path, width, height):
    folder = tmp_path / "frames"
    folder.mkdir()
    iio.imwrite(folder / "000000.png", np.zeros((8, 8, 3), np.uint8))
    (folder / "000001.png").write_bytes(_png_header(width, height))
    with pytest.raises(SkeletonMambaError) as info:
        read_video_frames(folder, 4)
    message = _one_line(info.value, folder / "000001.png")
    assert f"than the {MAX_IMAGE_PIXELS / 1e6:g} megapixels admitted" in message
    assert MAX_IMAGE_PIXELS == 40_000_000


def test_bad_images_and_videos_are_refused_on_one_line(tmp_path):
    iio.imwrite(tmp_path / "ok.png", np.zeros((8, 8, 3), np.uint8))
    (tmp_path / "cut.png").write_bytes((tmp_path / "ok.png").read_bytes()[:40])
    (tmp_path / "text.png").write_text("not an image")
    (tmp_path / "junk.mp4").write_bytes(b"\0junk" * 200)
    for name in ("cut.png", "text.png"):
        with pytest.raises(SkeletonMambaError) as info:
            read_image(tmp_path / name)
        _one_line(info.value, tmp_path / name)
    with pytest.raises(SkeletonMambaError) as info:
        read_video_frames(tmp_path / "junk.mp4", 4)
    assert "not a readable video" in _one_line(info.value, tmp_path / "junk.mp4")
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    iio.imwrite(mixed / "a.png", np.zeros((8, 8, 3), np.uint8))
    iio.imwrite(mixed / "b.png", np.zeros((8, 10, 3), np.uint8))
    with pytest.raises(SkeletonMambaError, match="frame 1 is 10x8, the first 8x8"):
        read_video_frames(mixed, 4)


def test_streamed_frames_equal_resizing_them_all_at_once(tmp_path):
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (37, 24, 40, 3), dtype=np.uint8)  # 37: two full chunks and a partial one
    for i, frame in enumerate(frames):
        iio.imwrite(tmp_path / f"{i:04d}.png", frame)
    expected = resize_frames(torch.from_numpy(frames).permute(0, 3, 1, 2).float() / 255.0, 16)
    torch.testing.assert_close(read_video_frames(tmp_path, 16), expected, rtol=0, atol=0)
    torch.testing.assert_close(read_video_frames(tmp_path, 16, max_frames=20), expected[:20], rtol=0, atol=0)
    assert [len(c) for c in iter_video_frames(tmp_path, 16)] == [16, 16, 5]


def _gradient_video(path: Path, num_frames: int, width: int = 320, height: int = 240) -> Path:
    x = np.linspace(0, 255, width, dtype=np.float32)[None, :, None]
    y = np.linspace(0, 255, height, dtype=np.float32)[:, None, None]
    writer = imageio_ffmpeg.write_frames(str(path), (width, height), fps=30, macro_block_size=16)
    writer.send(None)  # start ffmpeg
    for t in range(num_frames):
        planes = [x + 0 * y, y + 0 * x, np.full((height, width, 1), (t * 7) % 256, np.float32)]
        writer.send(np.ascontiguousarray(np.concatenate(planes, axis=-1).astype(np.uint8)))
    writer.close()
    return path


_PEAK_RSS = PEAK_KIB_SOURCE + textwrap.dedent(
    """
    import sys
    from skeleton_mamba.tasks.egodance.frames import iter_video_frames
    peaks = []
    for path in sys.argv[1:]:
        count = sum(len(chunk) for chunk in iter_video_frames(path, 8))
        peaks.append((count, peak_kib()))
    print(peaks)
    """
)


def test_video_reader_memory_does_not_grow_with_the_length(tmp_path):
    """Peak RSS (KiB, one fresh interpreter) after decoding 300 frames of 320x240, then 1000: holding the
    frames would add 700 * 230 KB = 161 MB as uint8 (644 MB as float). The first pass also pays the
    decoder's, the resize's and the allocator's one-time costs, which do not grow with the length."""
    paths = [_gradient_video(tmp_path / f"v{frames}.mp4", frames) for frames in (300, 1000)]
    growths = []
    for _ in range(2):  # the smaller of two fresh interpreters: held frames show in both; a one-off growth
        # (32 MB, once, in CI's suite; not reproduced alone nor beside two busy processes) in one only
        proc = subprocess.run([sys.executable, "-c", _PEAK_RSS, *map(str, paths)], capture_output=True,
                              text=True, timeout=300, check=True)  # fmt: skip
        (short, after_short), (long, after_long) = ast.literal_eval(proc.stdout.strip())
        assert (short, long) == (300, 1000)
        growths.append(after_long - after_short)
        if growths[-1] < 16 * 1024:
            break
    assert min(growths) < 16 * 1024, growths  # a tenth of the frames as uint8


def test_decoded_video_frames_match_what_was_written(tmp_path):
    path = _gradient_video(tmp_path / "v.mp4", 20, 64, 48)
    frames = read_video_frames(path, (48, 64))  # the source size: no resizing
    assert frames.shape == (20, 3, 48, 64)
    x = torch.linspace(0, 1, 64)
    assert (frames[:, 0] - x).abs().mean() < 0.03  # red is the horizontal ramp (lossy H.264)


# ---------------------------------------------------------------------------------------------- Kinetics


def _clip(**override) -> dict:
    person = {"pose": [0.5] * 36, "score": [0.9] * 18}
    clip = {"data": [{"frame_index": 1, "skeleton": [person]}], "label": "abseiling", "label_index": 0}
    clip.update(override)
    return clip


HOSTILE_KINETICS = {
    "nested_100000": ("[" * 100_000 + "]" * 100_000, "nested more than 16 levels deep"),
    "digits_5000": (json.dumps(_clip())[:-1] + ', "x": ' + "7" * 5000 + "}", "an integer of 5000 digits"),
    "label_1e9": (json.dumps(_clip(label_index=10**9)), "'label_index' must be a 0-based integer below"),
    "string_pose": (json.dumps(_clip(data=[{"frame_index": 1, "skeleton": [{"pose": ["0.5"] * 36,
                                             "score": [0.9] * 18}]}])), "entry 0 is str '0.5', not a number"),
    "bool_score": (json.dumps(_clip(data=[{"frame_index": 1, "skeleton": [{"pose": [0.5] * 36,
                                            "score": [True] * 18}]}])), "entry 0 is bool"),
    "brackets_in_strings": (json.dumps(_clip(label="[" * 100)), None),  # strings do not count as nesting
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(HOSTILE_KINETICS))
def test_hostile_kinetics_json_is_refused_on_one_line(tmp_path, case):
    text, expected = HOSTILE_KINETICS[case]
    path = tmp_path / "clip.json"
    path.write_text(text, encoding="utf-8")
    if expected is None:
        keypoint, _, label, name = read_kinetics_clip(path)
        assert keypoint.shape == (1, 1, 18, 2) and label == 0 and name == "[" * 100
        return
    with pytest.raises(SkeletonMambaError) as info:
        read_kinetics_clip(path)
    assert expected in _one_line(info.value, path)


def test_kinetics_label_file_refuses_huge_indices(tmp_path):
    path = tmp_path / "kinetics_train_label.json"
    path.write_text(json.dumps({"v1": {"has_skeleton": True, "label_index": 10**9}}), encoding="utf-8")
    with pytest.raises(SkeletonMambaError) as info:
        read_kinetics_labels(path)
    assert "below 100000" in _one_line(info.value, path)
