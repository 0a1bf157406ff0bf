"""NTU RGB+D raw skeleton parser, sample names, body selection and official splits."""

from __future__ import annotations

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.formats.ntu import SkeletonFileError, parse_ntu_name, read_skeleton_file
from skeleton_mamba.tasks.recognition.splits import (
    benchmark_splits,
    in_dataset,
    load_missing_samples,
    sample_splits,
)
from tests.helpers.motions import STANDING, as_written, body_motion, skeleton_text, write_skeleton

BODY_ID = 72057594037931101  # needs 64 bits: a float cast would change it


# --- the real sample ---------------------------------------------------------------------------------


def test_real_sample_matches_its_own_text(shared_data):
    path = shared_data / "ntu" / "S001C001P001R001A001.skeleton"
    lines = path.read_bytes().decode("ascii").split("\r\n")
    seq = read_skeleton_file(path)
    assert seq.num_frames == int(lines[0]) == 103
    assert len(seq.bodies) == 1 and seq.bodies[0].body_id == int(lines[2].split()[0])
    kp = seq.keypoints()
    assert kp.shape == (1, 103, 25, 3) and kp.dtype == np.float32
    # one body per frame: each frame is bodycount + body line + jointcount + 25 joint lines = 28 lines
    for frame, joint in [(0, 0), (0, 3), (50, 11), (102, 24)]:
        start = 1 + 28 * frame  # 0-based index of the frame's bodycount line
        assert lines[start] == "1" and lines[start + 2] == "25"
        values = lines[start + 3 + joint].split()
        assert len(values) == 12
        np.testing.assert_array_equal(kp[0, frame, joint], np.array(values[:3], dtype=np.float32))
        np.testing.assert_array_equal(seq.frames[frame].bodies[0].joints[joint], np.array(values, float))


# --- generated files -----------------------------------------------------------------------------------


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_generated_file_with_several_bodies_and_empty_frames(tmp_path, newline):
    a, b = body_motion(6, 0.2, seed=1), body_motion(4, 0.05, shift=1.0, seed=2)
    frames = [[], [(BODY_ID, a[0])], [(BODY_ID, a[1]), (7, b[0])], [], [(BODY_ID, a[2]), (7, b[1])],
              [(7, b[2])], [(BODY_ID, a[3])], []]  # fmt: skip
    seq = read_skeleton_file(write_skeleton(tmp_path / "S001C001P001R001A001.skeleton", frames, newline))
    assert seq.num_frames == 8 and seq.num_nonempty_frames == 5
    assert [len(f.bodies) for f in seq.frames] == [0, 1, 2, 0, 2, 1, 1, 0]
    assert [body.body_id for body in seq.bodies] == [BODY_ID, 7]
    first, second = seq.bodies
    assert first.frame_indices == [1, 2, 4, 6] and first.start == 0
    assert second.frame_indices == [2, 4, 5] and second.start == 1  # timeline skips empty frames
    np.testing.assert_array_equal(first.xyz, as_written(a[:4].reshape(-1, 3)).reshape(4, 25, 3))
    raw = seq.frames[2].bodies[1]
    assert raw.body_id == 7 and raw.joints.shape == (25, 12)
    np.testing.assert_array_equal(raw.joints[:, 11], [1 + j % 2 for j in range(25)])  # trackingState
    np.testing.assert_allclose(raw.info, [0, 1, 1, 1, 1, 0, 0.02764709, 0.05745083, 2])


def test_body_selection_follows_pyskl(tmp_path):
    """Rank by motion, drop short and wide (noise) bodies, fill 2 slots greedily, trim empty frames."""
    T = 40
    big = body_motion(T, 0.3, seed=3)  # most motion -> slot 0
    early = body_motion(20, 0.1, shift=1.0, seed=4)  # frames 0-19, overlaps big -> slot 1
    late = body_motion(20, 0.05, shift=-1.0, seed=5)  # frames 20-39, fits after `early` in slot 1
    short = body_motion(8, 0.9, shift=2.0, seed=6)  # 8 <= 11 frames: dropped despite its motion
    wide = body_motion(T, 0.6, shift=3.0, seed=7)
    wide[..., 0] *= 10.0  # x-range > 0.8 y-range in every frame: Kinect noise, dropped
    frames = []
    for t in range(T):
        bodies = [(1, big[t]), (5, wide[t])]
        bodies += [(2, early[t])] if t < 20 else [(3, late[t - 20])]
        bodies += [(4, short[t])] if t < 8 else []
        frames.append(bodies)
    seq = read_skeleton_file(write_skeleton(tmp_path / "S001C001P001R001A050.skeleton", frames))
    kp = seq.keypoints(max_bodies=2)
    assert kp.shape == (2, T, 25, 3)
    np.testing.assert_allclose(kp[0], big, atol=1e-6)
    np.testing.assert_allclose(kp[1, :20], early, atol=1e-6)
    np.testing.assert_allclose(kp[1, 20:], late, atol=1e-6)


def test_single_body_and_leading_trailing_trim(tmp_path):
    a, b = body_motion(30, 0.3, seed=8), body_motion(15, 0.1, shift=1.0, seed=9)
    frames = [[(1, a[t])] + ([(2, b[t - 10])] if 10 <= t < 25 else []) for t in range(30)]
    kp = read_skeleton_file(write_skeleton(tmp_path / "S001C001P001R001A050.skeleton", frames)).keypoints()
    assert kp.shape == (2, 30, 25, 3)
    assert not kp[1, :10].any() and kp[1, 10:25].any() and not kp[1, 25:].any()
    only = read_skeleton_file(write_skeleton(tmp_path / "one.skeleton", [[], [(9, a[0])], [(9, a[1])], []]))
    assert only.keypoints().shape == (1, 2, 25, 3)
    empty = read_skeleton_file(write_skeleton(tmp_path / "none.skeleton", [[], []]))
    assert empty.num_frames == 2 and empty.keypoints().shape == (0, 0, 25, 3)


# --- malformed files -----------------------------------------------------------------------------------


def _lines(frames):
    return skeleton_text(frames, "\n").splitlines()


def _expect_error(tmp_path, lines, line_no, *words):
    path = tmp_path / "S001C001P001R001A001.skeleton"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(SkeletonFileError) as info:
        read_skeleton_file(path)
    message = str(info.value)
    assert str(path) in message and f"line {line_no}:" in message, message
    for word in words:
        assert word in message, message


def test_truncated_file_names_file_and_line(tmp_path):
    lines = _lines([[(1, STANDING)], [(1, STANDING)]])  # 2 frames x 28 lines + the frame count = 57 lines
    assert len(lines) == 57  # frame 2: body count on line 30, body line 31, joint count 32, joints 33-57
    _expect_error(tmp_path, lines[:40], 41, "file ends early", "joint 9 of body 1 of 1 in frame 2")
    _expect_error(tmp_path, lines[:29], 30, "file ends early", "body count of frame 2")
    _expect_error(tmp_path, lines[:30], 31, "file ends early", "body line")


def test_malformed_lines_name_file_and_line(tmp_path):
    lines = _lines([[(1, STANDING)], [(1, STANDING)]])
    bad_joint = lines.copy()
    bad_joint[9] = " ".join(bad_joint[9].split()[:11])  # line 10 = joint 6 of frame 1, one value short
    _expect_error(tmp_path, bad_joint, 10, "joint 6", "12 numbers", "got 11 values")
    not_number = lines.copy()
    not_number[9] = not_number[9].replace(not_number[9].split()[1], "abc", 1)
    _expect_error(tmp_path, not_number, 10, "joint 6")
    bad_count = lines.copy()
    bad_count[29] = "two"  # bodycount of frame 2
    _expect_error(tmp_path, bad_count, 30, "body count of frame 2", "'two'")
    bad_joints = lines.copy()
    bad_joints[3] = "24"
    _expect_error(tmp_path, bad_joints, 4, "joint count", "25")
    _expect_error(tmp_path, lines + ["1"], 58, "after the last of 2 frames")


# --- names and splits ------------------------------------------------------------------------------------


def test_parse_ntu_name():
    expected = {"setup": 1, "camera": 2, "performer": 3, "replication": 2, "action": 13}
    assert parse_ntu_name("S001C002P003R002A013") == expected
    assert parse_ntu_name("/data/nturgb+d_skeletons/S001C002P003R002A013.skeleton") == expected
    assert parse_ntu_name("S032C003P106R002A120")["action"] == 120
    with pytest.raises(ValueError, match="not an NTU sample name"):
        parse_ntu_name("S01C002P003R002A013")


def test_official_split_membership():
    # X-Sub training subjects include 1, 2, 4; 3 and 40 are test subjects; X-View trains on cameras 2, 3
    assert sample_splits("S001C001P001R001A001", "ntu60") == ("xsub_train", "xview_val")
    assert sample_splits("S005C002P003R002A010", "ntu60") == ("xsub_val", "xview_train")
    assert sample_splits("S017C003P040R001A060", "ntu60") == ("xsub_val", "xview_train")
    assert sample_splits("S010C003P038R001A020", "ntu60") == ("xsub_train", "xview_train")
    # NTU120: X-Set trains on even setups; subjects 45 and 103 train, 41 and 106 are test subjects
    assert sample_splits("S018C001P045R001A061", "ntu120") == ("xsub_train", "xset_train")
    assert sample_splits("S019C001P041R001A001", "ntu120") == ("xsub_val", "xset_val")
    assert sample_splits("S032C002P103R002A120", "ntu120") == ("xsub_train", "xset_train")
    assert sample_splits("S031C002P106R002A120", "ntu120") == ("xsub_val", "xset_val")
    assert not in_dataset("S018C001P045R001A061", "ntu60") and not in_dataset("S001C001P001R001A061", "ntu60")
    with pytest.raises(ValueError, match="not a sample of ntu60"):
        sample_splits("S001C001P001R001A061", "ntu60")
    split = benchmark_splits(["S001C001P001R001A001", "S001C002P003R001A001"], "ntu60")
    a, b = "S001C001P001R001A001", "S001C002P003R001A001"
    assert split == {"xsub_train": [a], "xsub_val": [b], "xview_train": [b], "xview_val": [a]}


def test_missing_skeleton_lists():
    ntu60, ntu120 = load_missing_samples("ntu60"), load_missing_samples("ntu120")
    assert len(ntu60) == 302 and len(ntu120) == 535 and ntu60 < ntu120
    assert {"S001C002P005R002A008", "S001C002P006R001A008", "S001C003P002R001A055"} <= ntu60
    assert max(ntu60) == "S017C003P020R001A059"
    assert all(parse_ntu_name(n)["setup"] <= 17 for n in ntu60)
    assert all(parse_ntu_name(n)["setup"] >= 18 for n in ntu120 - ntu60)
