"""Every reader of outside data refuses NaN / Inf / overflow naming file and place, and bounds its counts."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.tasks.motion.formats.aistpp import load_aistpp_motion
from skeleton_mamba.tasks.motion.formats.bvh import BvhError, load_bvh
from skeleton_mamba.tasks.motion.formats.humanml3d_features import NonFiniteFeaturesError, read_features
from skeleton_mamba.tasks.motion.formats.motion_file import (
    MotionData,
    MotionFileError,
    load_motion,
    save_motion,
)
from skeleton_mamba.tasks.motion.formats.ntu import SkeletonFileError, read_skeleton_file
from skeleton_mamba.tasks.motion.io.value_checks import check_fps, load_npy, non_finite_message
from skeleton_mamba.tasks.motion.music.features import load_audio
from skeleton_mamba.tasks.motion.render.skeleton import render_motion
from skeleton_mamba.tasks.recognition.kinetics import KineticsFileError, read_kinetics_clip
from skeleton_mamba.tasks.recognition.pyskl import AnnotationFileError, save_annotations
from skeleton_mamba.tasks.text2motion.humanml3d import load_clips
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.motions import HAND_BVH
from tests.helpers.repo import shared_file

NTU_SAMPLE = "ntu/S001C001P001R001A001.skeleton"
POISONS = ["nan", "-inf", "1e999", "1e39"]  # 1e39 is finite in float64 but Inf once stored as float32


def _poison_token(text: str, line: int, column: int, token: str) -> str:
    lines = text.splitlines()
    values = lines[line - 1].split()
    values[column] = token
    lines[line - 1] = " ".join(values)
    return "\r\n".join(lines) + "\r\n"


def test_all_reader_errors_are_data_file_errors():
    for error in (SkeletonFileError, KineticsFileError, AnnotationFileError, BvhError, MotionFileError,
                  NonFiniteFeaturesError):  # fmt: skip
        assert issubclass(error, DataFileError) and issubclass(error, ValueError)


def test_non_finite_message_names_the_first_bad_entry():
    values = np.zeros((4, 3, 2), np.float32)
    values[2, 1, 0], values[3, 0, 1] = np.inf, np.nan
    message = non_finite_message(values, "joints", ("frame", "joint"))
    assert message == "joints: inf at frame 2, joint 1 (0-based; 2 non-finite values)"
    assert non_finite_message(np.arange(3), "ints") is None and non_finite_message(values[:2], "x") is None


# --- NTU ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("token", POISONS)
def test_ntu_joint_value_that_is_not_finite_is_refused_with_its_line(tmp_path, token):
    text = shared_file(NTU_SAMPLE).read_text()
    path = tmp_path / "S001C001P001R001A001.skeleton"
    path.write_text(_poison_token(text, 40, 1, token), newline="")  # line 40: a joint line of frame 2
    where = rf"{path}: line 40: joint \d+ of body 1 of 1 in frame 2: y ="
    with pytest.raises(SkeletonFileError, match=where):
        read_skeleton_file(path)


def test_ntu_body_line_and_absurd_frame_count(tmp_path):
    text = shared_file(NTU_SAMPLE).read_text()
    path = tmp_path / "S001C001P001R001A001.skeleton"
    path.write_text(_poison_token(text, 3, 7, "nan"), newline="")  # leanX of the first body
    with pytest.raises(SkeletonFileError, match="line 3: the body line of body 1 of 1 in frame 1 holds a"):
        read_skeleton_file(path)
    path.write_text("1000000000000\r\n" + "\r\n".join(text.splitlines()[1:]), newline="")
    with pytest.raises(SkeletonFileError, match="line 1: 1000000000000 frames declared, but only 2884 lines"):
        read_skeleton_file(path)


def test_prepare_refuses_or_skips_a_file_with_one_nan(tmp_path, capsys):
    text = shared_file(NTU_SAMPLE).read_text()
    raw = tmp_path / "raw"
    raw.mkdir()
    (raw / "S001C001P001R001A001.skeleton").write_text(text, newline="")
    bad = raw / "S001C002P003R002A013.skeleton"
    bad.write_text(_poison_token(text, 100, 2, "nan"), newline="")
    out = tmp_path / "ntu60.pkl"
    assert sm_main(["prepare", "ntu60", "--raw", str(raw), "--out", str(out), "--workers", "1"]) != 0
    err = capsys.readouterr().err
    assert f"{bad}: line 100:" in err and "z = nan" in err and not out.exists()
    code = sm_main(["prepare", "ntu60", "--raw", str(raw), "--out", str(out), "--workers", "1", "--skip-bad"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "wrote 1 samples" in printed and "bad: 1" in printed
    with open(out, "rb") as f:
        data = pickle.load(f)  # noqa: S301 - the file this test just wrote
    assert [a["frame_dir"] for a in data["annotations"]] == ["S001C001P001R001A001"]
    assert np.isfinite(data["annotations"][0]["keypoint"]).all()


# --- Kinetics and PYSKL ------------------------------------------------------------------------------


def _clip(pose_value=0.5, frame_indices=(1, 2)) -> dict:
    person = {"pose": [0.5] * 36, "score": [0.9] * 18}
    frames = [{"frame_index": i, "skeleton": [json.loads(json.dumps(person))]} for i in frame_indices]
    frames[-1]["skeleton"][0]["pose"][7] = pose_value
    return {"data": frames, "label": "abseiling", "label_index": 0}


def test_kinetics_pose_beyond_float32_is_refused_with_its_entry(tmp_path):
    path = tmp_path / "clip.json"
    path.write_text(json.dumps(_clip(1e39)))
    with pytest.raises(KineticsFileError, match=r"clip.json: data\[1\].skeleton\[0\].pose: value: .* 7"):
        read_kinetics_clip(path)


@pytest.mark.parametrize("value, token", [(float("nan"), "NaN"), (float("inf"), "Infinity")])
def test_kinetics_non_finite_pose_is_refused_at_its_line_and_column(tmp_path, value, token):
    path = tmp_path / "clip.json"
    text = json.dumps(_clip(value))
    path.write_text(text)
    column = text.index(token) + 1  # one line of JSON: the column is the token's offset + 1
    with pytest.raises(KineticsFileError, match=rf"clip.json:1:{column}: {token} is not a finite number"):
        read_kinetics_clip(path)


def test_kinetics_absurd_frame_index_span_and_nested_lists(tmp_path):
    path = tmp_path / "clip.json"
    path.write_text(json.dumps(_clip(frame_indices=(1, 10**12))))
    with pytest.raises(KineticsFileError, match="frame_index runs from 1 to 1000000000000"):
        read_kinetics_clip(path)
    clip = _clip()
    clip["data"][0]["skeleton"][0]["score"] = [[0.5, 0.5]] * 18
    path.write_text(json.dumps(clip))
    with pytest.raises(KineticsFileError, match=r"score: entry 0 is list '\[0.5, 0.5\]', not a number"):
        read_kinetics_clip(path)


def test_pyskl_annotation_with_nan_is_never_written(tmp_path):
    keypoint = np.zeros((1, 5, 25, 3), np.float32)
    keypoint[0, 3, 4, 2] = np.nan
    annotation = {"frame_dir": "a", "label": 0, "keypoint": keypoint, "total_frames": 5}
    data = {"split": {"train": ["a"]}, "annotations": [annotation]}
    with pytest.raises(AnnotationFileError, match=r"annotation 0 \(a\): keypoint: nan at body 0, frame 3"):
        save_annotations(data, tmp_path / "a.pkl")
    assert not (tmp_path / "a.pkl").exists()


# --- BVH ---------------------------------------------------------------------------------------------


def _bvh(tmp_path, frames="1", frame_time="0.04", rows=("1 2 3 0 0 0 0 0 0",)):
    text = HAND_BVH.format(order="Xrotation Yrotation Zrotation", values="\n".join(rows))
    text = text.replace("Frames: 1", f"Frames: {frames}")
    text = text.replace("Frame Time: 0.04", f"Frame Time: {frame_time}")
    path = tmp_path / "clip.bvh"
    path.write_text(text)
    return path


def test_bvh_frame_count_must_match_the_data_lines(tmp_path):
    rows = ["1 2 3 0 0 0 0 0 0"] * 5
    with pytest.raises(BvhError, match="Frames says 2 but 5 data lines follow"):
        load_bvh(_bvh(tmp_path, frames="2", rows=rows))
    with pytest.raises(BvhError, match=r"clip.bvh:\d+: Frames says 0: a BVH file needs at least one frame"):
        load_bvh(_bvh(tmp_path, frames="0", rows=()))
    assert load_bvh(_bvh(tmp_path, frames="5", rows=rows)).num_frames == 5


@pytest.mark.parametrize("frame_time", ["1e-9", "0", "-0.04", "1e9", "nan", "inf"])
def test_bvh_frame_time_outside_1_to_1000_fps_is_refused(tmp_path, frame_time):
    with pytest.raises(BvhError, match=r"Frame Time .* is outside \[0.001, 1\] s"):
        load_bvh(_bvh(tmp_path, frame_time=frame_time))


@pytest.mark.parametrize("token", ["nan", "inf", "1e999"])
def test_bvh_non_finite_values_are_refused_with_their_line(tmp_path, token):
    rows = ["1 2 3 0 0 0 0 0 0", f"1 2 3 0 {token} 0 0 0 0"]
    with pytest.raises(BvhError, match=r"clip.bvh:20: frame 2, channel 5: .* \(NaN and Inf are refused\)"):
        load_bvh(_bvh(tmp_path, frames="2", rows=rows))
    path = tmp_path / "offset.bvh"
    path.write_text(_bvh(tmp_path).read_text().replace("OFFSET 1 0 0", f"OFFSET 1 {token} 0"))
    with pytest.raises(BvhError, match=r"offset.bvh:8: expected 3 finite numbers"):
        load_bvh(path)


def test_render_refuses_frame_rates_that_would_grow_allocations(tmp_path, capsys):
    joints = np.zeros((3, 2, 3))
    with pytest.raises(ValueError, match="fps 1e\\+09 is outside 1-1000 frames per second"):
        render_motion(joints, [-1, 0], tmp_path / "a.mp4", fps=1e9)
    with pytest.raises(ValueError, match="outside"):
        check_fps(0.001)
    motion = save_motion(tmp_path / "m.npz", MotionData(30.0, "smpl24", joints=np.zeros((3, 24, 3))))
    with pytest.raises(SystemExit) as info:  # range-checked where parsed: argparse's usage and error line
        sm_main(["render", str(motion), "--out", str(tmp_path / "a.mp4"), "--fps", "1e7"])
    assert info.value.code == 2
    assert "argument --fps: expected a frame rate (frames per second) from 1 to 1000, got 1e7" in (
        capsys.readouterr().err
    )
    assert sm_main(["render", str(_bvh(tmp_path, frame_time="1e-9")), "--out", str(tmp_path / "b.mp4")]) == 2
    assert "Frame Time 1e-09 s is outside" in capsys.readouterr().err
    assert not (tmp_path / "a.mp4").exists() and not (tmp_path / "b.mp4").exists()


# --- motion files, AIST++, HumanML3D, music --------------------------------------------------------------


def test_motion_npz_and_aistpp_pkl_name_the_frame_of_a_nan(tmp_path):
    joints = np.zeros((6, 24, 3), np.float32)
    joints[4, 2, 1] = np.inf
    path = tmp_path / "m.npz"
    np.savez(path, fps=np.asarray(30.0), skeleton=np.asarray("smpl24"), joints=joints)
    with pytest.raises(MotionFileError, match=r"m.npz: joints: inf at frame 4, joint 2"):
        load_motion(path)
    np.savez(path, fps=np.asarray(1e9), skeleton=np.asarray("smpl24"), joints=np.zeros_like(joints))
    with pytest.raises(MotionFileError, match="fps 1e\\+09 is outside"):
        load_motion(path)
    poses = np.zeros((6, 72))
    poses[3, 5] = 1e39  # finite in float64, Inf in the float32 the loader keeps
    pkl = tmp_path / "gBR_sBM_cAll_d04_mBR0_ch01.pkl"
    with open(pkl, "wb") as f:
        pickle.dump({"smpl_poses": poses, "smpl_trans": np.zeros((6, 3)), "smpl_scaling": np.ones(1)}, f)
    with pytest.raises(MotionFileError, match=r"ch01.pkl: poses: inf at frame 3, joint 1"):
        load_aistpp_motion(pkl)


def test_humanml3d_motions_with_nan_are_left_out_with_a_count(tmp_path):
    (tmp_path / "new_joint_vecs").mkdir()
    (tmp_path / "texts").mkdir()
    for name in ("000001", "007975", "M007975"):
        features = np.zeros((60, 263), np.float32)
        if "7975" in name:
            features[10:, 5] = np.nan  # as the released 007975 and its mirror
        np.save(tmp_path / "new_joint_vecs" / f"{name}.npy", features)
        (tmp_path / "texts" / f"{name}.txt").write_text("a person walks.#a/DET#0.0#0.0\n")
    (tmp_path / "train.txt").write_text("000001\n007975\nM007975\n")
    expected = "HumanML3D train: left out 2 motions with NaN or Inf features: 007975, M007975"
    with pytest.warns(UserWarning, match=expected):
        clips = load_clips(tmp_path, "train")
    assert [c.motion_id for c in clips] == ["000001"]
    with pytest.raises(NonFiniteFeaturesError, match=r"007975.npy: features: nan at frame 10, column 5"):
        read_features(tmp_path / "new_joint_vecs" / "007975.npy")


def test_sm_convert_refuses_nan_features_and_truncated_files(tmp_path, capsys):
    features = np.zeros((4, 263), np.float32)
    features[2, 100] = np.nan
    np.save(tmp_path / "f.npy", features)
    assert sm_main(["convert", str(tmp_path / "f.npy"), "--out", str(tmp_path / "j.npy")]) == 2
    assert "f.npy: features: nan at frame 2, column 100" in capsys.readouterr().err
    assert not (tmp_path / "j.npy").exists()
    raw = (tmp_path / "f.npy").read_bytes()
    (tmp_path / "f.npy").write_bytes(raw[:-10])
    with pytest.raises(DataFileError, match=r"header says \(4, 263\) float32 \(4208 bytes\) but 4198 bytes"):
        load_npy(tmp_path / "f.npy")


def test_audio_with_nan_samples_is_refused_with_the_time(tmp_path):
    import soundfile as sf

    y = np.zeros((48000, 2), np.float32)
    y[36000, 1] = np.nan
    sf.write(tmp_path / "a.wav", y, 48000, subtype="FLOAT")
    with pytest.raises(DataFileError, match=r"a.wav: audio samples are NaN or Inf, the first .nan. at 0.750"):
        load_audio(tmp_path / "a.wav", 15360)
    y[36000, 1] = 0.0
    sf.write(tmp_path / "a.wav", y, 48000, subtype="FLOAT")
    assert load_audio(tmp_path / "a.wav", 15360).shape == (15360,)


def test_humanml3d_statistics_must_be_finite_and_std_positive(tmp_path):
    from skeleton_mamba.tasks.motion.formats.humanml3d_features import read_statistics

    np.save(tmp_path / "Mean.npy", np.zeros(263, np.float32))
    std = np.ones(263, np.float32)
    std[17] = np.inf
    np.save(tmp_path / "Std.npy", std)
    with pytest.raises(DataFileError, match=r"Std.npy: Std: inf at column 17"):
        read_statistics(tmp_path)
    std[17] = 0.0
    np.save(tmp_path / "Std.npy", std)
    with pytest.raises(DataFileError, match=r"Std.npy: Std must be positive, column 17 is 0.0"):
        read_statistics(tmp_path)


def test_kinetics_label_file_needs_integer_labels(tmp_path):
    from skeleton_mamba.tasks.recognition.kinetics import read_kinetics_labels

    path = tmp_path / "labels.json"
    path.write_text(json.dumps({"abc": {"has_skeleton": True, "label_index": "3"}}))
    message = r"'abc': 'label_index' must be a 0-based integer below 100000, got '3'"
    with pytest.raises(KineticsFileError, match=message):
        read_kinetics_labels(path)


def test_glove_vectors_with_nan_are_refused(tmp_path):
    from skeleton_mamba.tasks.text2motion.glove import WordVectorizer

    vectors = np.zeros((2, 300), np.float32)
    vectors[1, 42] = np.nan
    np.save(tmp_path / "our_vab_data.npy", vectors)
    for name, value in (("words", ["unk", "walk"]), ("idx", {"unk": 0, "walk": 1})):
        with open(tmp_path / f"our_vab_{name}.pkl", "wb") as f:
            pickle.dump(value, f)
    with pytest.raises(DataFileError, match=r"our_vab_data.npy: vectors: nan at row 1"):
        WordVectorizer(tmp_path)
