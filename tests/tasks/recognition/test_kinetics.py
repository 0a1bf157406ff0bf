"""Kinetics-skeleton (ST-GCN JSON layout) reader and ``sm prepare kinetics``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from skeleton_mamba.tasks.recognition.kinetics import KineticsFileError, read_kinetics_clip
from skeleton_mamba.tasks.recognition.pyskl import load_annotations
from skeleton_mamba.tasks.training.cli import main as sm_main


def person(seed: int, score: float) -> dict:
    """One OpenPose-18 person: 36 pose values in [0, 1] and 18 scores all equal to ``score``."""
    rng = np.random.default_rng(seed)
    return {"pose": [round(float(v), 3) for v in rng.uniform(0.1, 0.9, 36)], "score": [score] * 18}


def write_clip(path: Path, frames: dict[int, list[dict]], label: str = "abseiling", index: int = 0) -> Path:
    data = [{"frame_index": i, "skeleton": people} for i, people in frames.items()]
    path.write_text(json.dumps({"data": data, "label": label, "label_index": index}))
    return path


def test_read_clip_sorts_people_per_frame_by_score(tmp_path):
    p_low, p_high, p_mid = person(1, 0.2), person(2, 0.9), person(3, 0.5)
    frames = {1: [p_low, p_high, p_mid], 2: [p_mid], 4: [p_high, p_low]}  # frame 3 missing, 1-based
    clip = write_clip(tmp_path / "clip.json", frames, "juggling", 7)
    keypoint, score, label, name = read_kinetics_clip(clip)
    assert (label, name) == (7, "juggling")
    assert keypoint.shape == (2, 4, 18, 2) and score.shape == (2, 4, 18) and keypoint.dtype == np.float32
    xy = lambda p: np.array(p["pose"], np.float32).reshape(18, 2)  # noqa: E731
    np.testing.assert_array_equal(keypoint[0, 0], xy(p_high))  # frame 1: 0.9 then 0.5, 0.2 dropped
    np.testing.assert_array_equal(keypoint[1, 0], xy(p_mid))
    np.testing.assert_array_equal(keypoint[0, 1], xy(p_mid))  # frame 2: one person
    assert not keypoint[1, 1].any() and not score[1, 1].any()
    assert not keypoint[:, 2].any()  # frame 3 absent from the file
    np.testing.assert_array_equal(score[:, 3, 0], np.float32([0.9, 0.2]))
    joint4 = np.float32([p_low["pose"][8], p_low["pose"][9]])  # joint 4 = (x8, y9) of the flat pose list
    np.testing.assert_array_equal(keypoint[1, 3, 4], joint4)


def test_read_clip_caps_people_in_and_out(tmp_path):
    people = [person(i, 0.1 * (i + 1)) for i in range(6)]  # the 6th (best score) is beyond num_person_in=5
    keypoint, score, _, _ = read_kinetics_clip(write_clip(tmp_path / "c.json", {0: people}))
    np.testing.assert_allclose(score[:, 0, 0], [0.5, 0.4], rtol=1e-6)
    single, _, _, _ = read_kinetics_clip(write_clip(tmp_path / "s.json", {0: [people[0]], 1: []}))
    assert single.shape == (1, 2, 18, 2)
    empty, _, _, _ = read_kinetics_clip(write_clip(tmp_path / "e.json", {0: [], 1: []}))
    assert empty.shape[0] == 0


@pytest.mark.parametrize(
    "content, words",
    [
        ("{not json", "not valid JSON"),
        (json.dumps({"data": [], "label": "x"}), "label_index"),
        (json.dumps({"data": [{"frame_index": 0, "skeleton": [{"pose": [0.1] * 34, "score": [1] * 18}]}],
                     "label": "x", "label_index": 1}), "data[0].skeleton[0].pose: expected a list of 36"),
        (json.dumps({"data": [{"frame_index": 0, "skeleton": []}, {"frame_index": 0, "skeleton": []}],
                     "label": "x", "label_index": 1}), "frame_index 0 appears twice"),
    ],
)  # fmt: skip
def test_malformed_clip_is_reported(tmp_path, content, words):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(KineticsFileError) as info:
        read_kinetics_clip(path)
    assert str(path) in str(info.value) and words in str(info.value)


def _kinetics_folder(root: Path) -> Path:
    labels = {}
    for part, ids in [("train", ["vid_a", "vid_b", "vid_empty"]), ("val", ["vid_c"])]:
        (root / f"kinetics_{part}").mkdir(parents=True)
        entries = {}
        for k, vid in enumerate(ids):
            index = 3 * k + (part == "val")
            has = vid != "vid_empty"
            if has:
                frames = {1: [person(k, 0.8)], 2: [person(k + 9, 0.7)]}
                write_clip(root / f"kinetics_{part}" / f"{vid}.json", frames, f"class {index}", index)
            entries[vid] = {"has_skeleton": has, "label": f"class {index}", "label_index": index}
        (root / f"kinetics_{part}_label.json").write_text(json.dumps(entries))
        labels.update(entries)
    return root


def test_prepare_kinetics(tmp_path, capsys):
    raw = _kinetics_folder(tmp_path / "kinetics-skeleton")
    out = tmp_path / "k.pkl"
    assert sm_main(["prepare", "kinetics", "--raw", str(raw), "--out", str(out), "--workers", "2"]) == 0
    assert "wrote 3 samples" in capsys.readouterr().out
    data = load_annotations(out)
    assert data["split"] == {"train": ["vid_a", "vid_b"], "val": ["vid_c"]}
    annos = {a["frame_dir"]: a for a in data["annotations"]}
    assert {k: a["label"] for k, a in annos.items()} == {"vid_a": 0, "vid_b": 3, "vid_c": 1}
    assert annos["vid_b"]["keypoint"].shape == (1, 2, 18, 2)
    assert annos["vid_b"]["keypoint_score"].shape == (1, 2, 18)
    np.testing.assert_allclose(annos["vid_b"]["keypoint"][0, 1].ravel(), person(10, 0.7)["pose"], rtol=1e-6)
    assert data["label_names"][:4] == ["class 0", "class 1", "", "class 3"]


def test_prepare_kinetics_label_mismatch_fails(tmp_path, capsys):
    raw = _kinetics_folder(tmp_path / "k")
    write_clip(raw / "kinetics_val" / "vid_c.json", {0: [person(0, 0.5)]}, "class 1", 5)  # label file says 1
    assert sm_main(["prepare", "kinetics", "--raw", str(raw), "--out", str(tmp_path / "o.pkl")]) == 2
    err = capsys.readouterr().err
    assert "vid_c.json" in err and "label_index 5 differs from 1" in err
