"""AIST++ motion pickles (restricted unpickling), motion .npz files, splits, music ids, windows."""

from __future__ import annotations

import builtins
import os
import pickle

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics_axis_angle
from skeleton_mamba.tasks.motion.formats.aistpp import (
    load_aistpp_motion,
    load_split,
    motion_windows,
    music_id,
    music_path,
    split_sequences,
    window_starts,
)
from skeleton_mamba.tasks.motion.formats.motion_file import (
    MotionData,
    MotionFileError,
    load_motion,
    save_motion,
)
from skeleton_mamba.tasks.motion.io.safe_pickle import UnsafePickleError, safe_load_pickle


def write_aistpp(path, frames=30, flat=True, scaling=93.7, seed=0):
    rng = np.random.default_rng(seed)
    poses = rng.normal(scale=0.3, size=(frames, 24, 3)).astype(np.float32)
    data = {
        "smpl_loss": np.float64(0.01),
        "smpl_poses": poses.reshape(frames, 72) if flat else poses,
        "smpl_scaling": np.array([scaling], dtype=np.float32),
        "smpl_trans": rng.normal(scale=50.0, size=(frames, 3)).astype(np.float32),
    }
    with open(path, "wb") as f:
        pickle.dump(data, f)
    return data, poses


@pytest.mark.parametrize("flat", [True, False])
def test_reads_an_aistpp_motion_pickle(tmp_path, flat):
    data, poses = write_aistpp(tmp_path / "gBR_sBM_cAll_d04_mBR0_ch01.pkl", flat=flat)
    motion = load_aistpp_motion(tmp_path / "gBR_sBM_cAll_d04_mBR0_ch01.pkl")
    assert motion.fps == 60.0 and motion.skeleton == "smpl24"
    np.testing.assert_array_equal(motion.poses, poses)
    np.testing.assert_allclose(motion.root_position(), data["smpl_trans"] / 93.7, rtol=1e-6)
    expected = smpl_forward_kinematics_axis_angle(
        torch.from_numpy(poses).double(), torch.from_numpy(data["smpl_trans"] / data["smpl_scaling"]).double()
    )
    np.testing.assert_allclose(motion.joint_positions(), expected.numpy(), atol=1e-5)


def test_bad_aistpp_contents_name_the_file(tmp_path):
    path = tmp_path / "broken.pkl"
    with open(path, "wb") as f:
        pickle.dump({"smpl_poses": np.zeros((4, 72)), "smpl_trans": np.zeros((4, 3))}, f)
    with pytest.raises(MotionFileError, match=r"broken\.pkl: missing keys \['smpl_scaling'\]"):
        load_aistpp_motion(path)
    with open(path, "wb") as f:
        pickle.dump(
            {"smpl_poses": np.zeros((4, 70)), "smpl_trans": np.zeros((4, 3)), "smpl_scaling": [1.0]}, f
        )
    with pytest.raises(MotionFileError, match=r"broken\.pkl: smpl_poses must be"):
        load_aistpp_motion(path)
    with open(path, "wb") as f:
        pickle.dump(
            {"smpl_poses": np.zeros((4, 72)), "smpl_trans": np.zeros((5, 3)), "smpl_scaling": [1.0]}, f
        )
    with pytest.raises(MotionFileError, match=r"broken\.pkl: arrays disagree on the number of frames"):
        load_aistpp_motion(path)


class _RunsShell:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


class _CallsEval:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (builtins.exec, (f"open({str(self.marker)!r}, 'w').close()",))


@pytest.mark.parametrize("payload", [_RunsShell, _CallsEval])
def test_malicious_pickle_is_refused_and_runs_nothing(tmp_path, payload):
    marker = tmp_path / "pwned"
    path = tmp_path / "gBR_sBM_cAll_d04_mBR0_ch01.pkl"
    with open(path, "wb") as f:
        pickle.dump({"smpl_poses": np.zeros((2, 72)), "evil": payload(marker)}, f)
    with pytest.raises(
        UnsafePickleError, match=r"gBR_sBM_cAll_d04_mBR0_ch01\.pkl: refusing to unpickle global"
    ):
        load_aistpp_motion(path)
    assert not marker.exists(), "the pickle's code ran"
    # Control: the plain unpickler does run it, so the test above would notice a leak.
    with open(path, "rb") as f:
        pickle.load(f)  # noqa: S301 - deliberate, inside tmp_path, to prove the payload is live
    assert marker.exists()


def test_safe_pickle_admits_numpy_and_plain_values_in_every_protocol(tmp_path):
    value = {
        "a": np.arange(6, dtype=np.float32).reshape(2, 3),
        "b": [1, 2.5, "x", (None, True)],
        "c": {3},
        "d": np.float64(2.0),
        "e": np.asfortranarray(np.ones((2, 3))),
        "f": b"raw",
        "g": np.array(["s"]),
    }
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        path = tmp_path / f"p{protocol}.pkl"
        path.write_bytes(pickle.dumps(value, protocol=protocol))
        loaded = safe_load_pickle(path)
        assert (
            loaded["b"] == value["b"] and loaded["c"] == {3} and loaded["f"] == b"raw" and loaded["d"] == 2.0
        )
        for key in ("a", "e", "g"):
            np.testing.assert_array_equal(loaded[key], value[key])
    # A pickle written by numpy 1.x names numpy.core.multiarray.
    old = pickle.dumps(np.arange(3), protocol=2).replace(b"numpy._core.multiarray", b"numpy.core.multiarray")
    (tmp_path / "old.pkl").write_bytes(old)
    np.testing.assert_array_equal(safe_load_pickle(tmp_path / "old.pkl"), np.arange(3))
    (tmp_path / "cut.pkl").write_bytes(old[:10])
    with pytest.raises(UnsafePickleError, match=r"cut\.pkl: not a readable data pickle"):
        safe_load_pickle(tmp_path / "cut.pkl")


def test_motion_npz_round_trip_and_validation(tmp_path):
    rng = np.random.default_rng(1)
    motion = MotionData(
        fps=30.0, poses=rng.normal(size=(5, 24, 3)), trans=rng.normal(size=(5, 3)), scaling=2.0
    )
    path = save_motion(tmp_path / "m.npz", motion)
    with np.load(path, allow_pickle=False) as raw:
        assert raw["smpl_poses"].shape == (5, 72) and raw["smpl_scaling"].shape == (1,)
        assert str(raw["skeleton"]) == "smpl24" and float(raw["fps"]) == 30.0
    back = load_motion(path)
    np.testing.assert_allclose(back.poses, motion.poses, atol=1e-6)
    np.testing.assert_allclose(back.root_position(), motion.trans / 2.0, atol=1e-6)
    joints = MotionData(fps=20.0, skeleton="humanml3d22", joints=rng.normal(size=(7, 22, 3)))
    assert load_motion(save_motion(tmp_path / "j.npz", joints)).joints.shape == (7, 22, 3)
    with pytest.raises(MotionFileError, match=r"bad\.npz: joints must be \(T, 22, 3\)"):
        save_motion(
            tmp_path / "bad.npz", MotionData(fps=20.0, skeleton="humanml3d22", joints=np.zeros((7, 24, 3)))
        )
    np.savez(tmp_path / "nofps.npz", smpl_poses=np.zeros((3, 72)), smpl_trans=np.zeros((3, 3)))
    with pytest.raises(MotionFileError, match=r"nofps\.npz: missing key 'fps'"):
        load_motion(tmp_path / "nofps.npz")


TEST_MUSIC = {"mBR0", "mHO5", "mJB5", "mJS3", "mKR2", "mLH4", "mLO2", "mMH3", "mPO1", "mWA0"}


def test_splits_ship_as_package_data():
    train, test, ignore = load_split("train"), load_split("test"), load_split("ignore")
    assert (len(train), len(test), len(ignore)) == (980, 20, 45)
    assert len(set(train)) == 980 and not set(train) & set(test)
    assert {music_id(n) for n in test} == TEST_MUSIC
    assert all(n.split("_")[1] == "sBM" and n.endswith("_ch02") for n in test)
    kept = split_sequences("train")
    assert not set(kept) & set(ignore) and kept == [n for n in train if n not in set(ignore)]
    with pytest.raises(FileNotFoundError, match="no AIST\\+\\+ crossmodal val list"):
        load_split("val")


def test_package_splits_equal_the_shared_copies(shared_data):
    folder = shared_data / "aistpp" / "splits"
    for name, split in (
        ("crossmodal_train", "train"),
        ("crossmodal_test", "test"),
        ("ignore_list", "ignore"),
    ):
        shared = [ln.strip() for ln in (folder / f"{name}.txt").read_text().splitlines() if ln.strip()]
        assert load_split(split) == shared


def test_music_pairing():
    assert music_id("gBR_sBM_cAll_d04_mBR0_ch01") == "mBR0"
    assert music_id("motions/gHO_sFM_cAll_d20_mHO5_ch13.pkl") == "mHO5"
    assert music_path("/music", "gJB_sBM_cAll_d07_mJB5_ch02").as_posix() == "/music/mJB5.wav"
    with pytest.raises(ValueError, match="not an AIST\\+\\+ sequence name"):
        music_id("dance_01")


def test_windows():
    assert window_starts(10, 4, 3) == [0, 3, 6]
    assert window_starts(3, 4, 1) == []
    rng = np.random.default_rng(2)
    motion = MotionData(fps=60.0, poses=rng.normal(size=(420, 24, 3)) * 0.3, trans=rng.normal(size=(420, 3)))
    windows = motion_windows(motion, fps=30.0, window_seconds=5.0, stride_seconds=0.5)
    # 7 s at 30 fps = 210 frames; 150-frame windows every 15 frames start at 0, 15, 30, 45, 60.
    assert len(windows) == 5 and all(w.num_frames == 150 and w.fps == 30.0 for w in windows)
    np.testing.assert_allclose(windows[1].poses, motion.poses[::2][15:165], atol=1e-6)
    np.testing.assert_allclose(windows[4].trans, motion.trans[::2][60:210], atol=1e-6)
