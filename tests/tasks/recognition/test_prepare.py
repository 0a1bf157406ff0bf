"""``sm prepare ntu60|ntu120``: raw folder -> PYSKL annotation file with the official splits."""

from __future__ import annotations

import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.io.safe_pickle import UnsafePickleError
from skeleton_mamba.tasks.recognition.pyskl import AnnotationFileError, load_annotations, save_annotations
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.motions import as_written, body_motion, write_skeleton

# name -> (X-Sub side, X-View side) for NTU60; subjects 1, 2, 8 train, 3, 40 test; cameras 2, 3 train
NTU60_SAMPLES = {
    "S001C001P001R001A001": ("xsub_train", "xview_val"),
    "S001C002P003R002A013": ("xsub_val", "xview_train"),
    "S002C003P008R001A060": ("xsub_train", "xview_train"),
    "S017C001P040R002A031": ("xsub_val", "xview_val"),
}
MISSING = "S001C002P005R002A008"  # first entry of the official NTU60 / NTU120 missing lists
NTU120_ONLY = {
    "S018C002P045R001A061": ("xsub_train", "xset_train"),
    "S019C001P041R001A002": ("xsub_val", "xset_val"),
}


def _frames(name: str, two_bodies: bool) -> list:
    seed = int(name[-3:]) + 7 * int(name[9:12])
    a = body_motion(30, 0.3, seed=seed)
    b = body_motion(30, 0.1, shift=1.0, seed=seed + 1)
    return [[(1, a[t])] + ([(2, b[t])] if two_bodies else []) for t in range(30)]


@pytest.fixture(scope="module")
def raw_folder(tmp_path_factory) -> Path:
    raw = tmp_path_factory.mktemp("nturgb+d_skeletons")
    names = [*NTU60_SAMPLES, MISSING, *NTU120_ONLY]
    for i, name in enumerate(names):
        sub = raw / ("s018_to_s032" if name in NTU120_ONLY else "")  # sub-folders are searched too
        sub.mkdir(exist_ok=True)
        write_skeleton(sub / f"{name}.skeleton", _frames(name, two_bodies=i % 2 == 0))
    return raw


def test_prepare_ntu60_in_process(raw_folder, tmp_path, capsys):
    out = tmp_path / "ntu60_3danno.pkl"
    assert sm_main(["prepare", "ntu60", "--raw", str(raw_folder), "--out", str(out), "--workers", "2"]) == 0
    report = capsys.readouterr().out
    assert "wrote 4 samples" in report and "missing excluded: 1" in report and "outside dataset: 2" in report
    data = load_annotations(out)
    expected = {key: sorted(n for n, sides in NTU60_SAMPLES.items() if key in sides)
                for key in ("xsub_train", "xsub_val", "xview_train", "xview_val")}  # fmt: skip
    assert data["split"] == expected
    annos = {a["frame_dir"]: a for a in data["annotations"]}
    assert sorted(annos) == sorted(NTU60_SAMPLES) and MISSING not in annos
    assert annos["S001C002P003R002A013"]["label"] == 12 and annos["S002C003P008R001A060"]["label"] == 59
    first = annos["S001C001P001R001A001"]  # written with two bodies; body 1 waves more -> slot 0
    assert first["keypoint"].shape == (2, 30, 25, 3) and first["total_frames"] == 30
    frames = _frames("S001C001P001R001A001", two_bodies=True)
    np.testing.assert_array_equal(first["keypoint"][0, 7], as_written(frames[7][0][1]))
    np.testing.assert_array_equal(first["keypoint"][1, 7], as_written(frames[7][1][1]))
    assert annos["S001C002P003R002A013"]["keypoint"].shape == (1, 30, 25, 3)


def test_prepare_ntu120_in_process(raw_folder, tmp_path, capsys):
    out = tmp_path / "ntu120.pkl"
    assert sm_main(["prepare", "ntu120", "--raw", str(raw_folder), "--out", str(out), "--workers", "1"]) == 0
    assert "missing excluded: 1" in capsys.readouterr().out
    data = load_annotations(out)
    everything = {n: (sides[0], "xset_train" if int(n[1:4]) % 2 == 0 else "xset_val")
                  for n, sides in NTU60_SAMPLES.items()} | NTU120_ONLY  # fmt: skip
    assert set(data["split"]) == {"xsub_train", "xsub_val", "xset_train", "xset_val"}
    for key, members in data["split"].items():
        assert members == sorted(n for n, sides in everything.items() if key in sides), key
    assert {a["frame_dir"]: a["label"] for a in data["annotations"]}["S018C002P045R001A061"] == 60


def test_prepare_the_real_sample(shared_data, tmp_path, capsys):
    out = tmp_path / "real.pkl"
    raw = shared_data / "ntu"  # read in place (the folder is read-only)
    assert sm_main(["prepare", "ntu60", "--raw", str(raw), "--out", str(out), "--workers", "1"]) == 0
    data = load_annotations(out)
    assert data["split"]["xsub_train"] == data["split"]["xview_val"] == ["S001C001P001R001A001"]
    assert data["split"]["xsub_val"] == data["split"]["xview_train"] == []
    (anno,) = data["annotations"]
    assert anno["label"] == 0 and anno["keypoint"].shape == (1, 103, 25, 3) and anno["total_frames"] == 103


def test_prepare_via_sm_subprocess(raw_folder, tmp_path):
    sm = shutil.which("sm") or str(Path(sys.executable).parent / "sm")
    out = tmp_path / "sub.pkl"
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    cmd = [sm, "prepare", "ntu60", "--raw", str(raw_folder), "--out", str(out)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert result.returncode == 0, result.stderr
    assert "wrote 4 samples" in result.stdout
    xview_val = load_annotations(out)["split"]["xview_val"]
    assert xview_val == ["S001C001P001R001A001", "S017C001P040R002A031"]


def test_bad_file_fails_or_is_skipped(raw_folder, tmp_path, capsys):
    raw = tmp_path / "raw"
    shutil.copytree(raw_folder, raw)
    bad = raw / "S001C001P001R001A001.skeleton"
    lines = bad.read_text().splitlines()
    bad.write_text("\n".join(lines[:100]) + "\n")  # truncated inside frame 4
    out = tmp_path / "out.pkl"
    args = ["prepare", "ntu60", "--raw", str(raw), "--out", str(out), "--workers", "2"]
    assert sm_main(args) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "line 101" in err and "file ends early" in err and "--skip-bad" in err
    assert not out.exists()
    assert sm_main([*args, "--skip-bad"]) == 0
    captured = capsys.readouterr()
    assert "warning: skipping S001C001P001R001A001" in captured.err and "bad: 1" in captured.out
    data = load_annotations(out)
    assert "S001C001P001R001A001" not in {a["frame_dir"] for a in data["annotations"]}
    assert data["split"]["xview_val"] == ["S017C001P040R002A031"]


def test_prepare_reports_an_empty_folder(tmp_path, capsys):
    assert sm_main(["prepare", "ntu60", "--raw", str(tmp_path), "--out", str(tmp_path / "x.pkl")]) == 2
    assert "no .skeleton files found" in capsys.readouterr().err


# --- PYSKL annotation files ---------------------------------------------------------------------------


def _pyskl_3d() -> dict:
    rng = np.random.default_rng(0)
    annos = [{"frame_dir": f"S001C00{c}P001R001A00{a}", "label": np.int64(a - 1), "total_frames": 20,
              "keypoint": rng.normal(size=(m, 20, 25, 3)).astype(np.float16)}
             for c, a, m in [(1, 1, 1), (2, 2, 2)]]  # fmt: skip
    names = [a["frame_dir"] for a in annos]
    return {"split": {"xview_train": names[1:], "xview_val": names[:1]}, "annotations": annos}


def test_load_pyskl_3d_and_2d_pickles(tmp_path):
    path = tmp_path / "ntu60_3danno.pkl"
    source = _pyskl_3d()
    path.write_bytes(pickle.dumps(source, protocol=pickle.HIGHEST_PROTOCOL))
    data = load_annotations(path)
    assert data["split"] == {"xview_train": ["S001C002P001R001A002"], "xview_val": ["S001C001P001R001A001"]}
    second = data["annotations"][1]
    assert second["label"] == 1 and type(second["label"]) is int and second["total_frames"] == 20
    assert second["keypoint"].dtype == np.float32 and second["keypoint"].shape == (2, 20, 25, 3)
    np.testing.assert_array_equal(second["keypoint"], source["annotations"][1]["keypoint"].astype(np.float32))
    two_d = {"split": {"train": ["clip"]}, "annotations": [{
        "frame_dir": "clip", "label": 5, "total_frames": 3, "img_shape": (1080, 1920),
        "keypoint": np.ones((1, 3, 17, 2), np.float32),
        "keypoint_score": np.full((1, 3, 17), 0.5)}]}  # fmt: skip
    path2d = tmp_path / "hrnet.pkl"
    path2d.write_bytes(pickle.dumps(two_d, protocol=2))
    anno = load_annotations(path2d)["annotations"][0]
    assert anno["keypoint_score"].dtype == np.float32 and anno["img_shape"] == (1080, 1920)


class _Exploit:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_malicious_pickle_is_refused(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "evil.pkl"
    path.write_bytes(pickle.dumps({"split": {}, "annotations": [_Exploit(marker)]}))
    with pytest.raises(UnsafePickleError, match="system"):
        load_annotations(path)
    assert not marker.exists()


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda d: d["annotations"][0].pop("keypoint"), "no 'keypoint'"),
        (lambda d: d["annotations"][0].update(total_frames=19), "'total_frames' (19)"),
        (lambda d: d["annotations"][0].update(label=-1), "0-based"),
        (lambda d: d["split"].update(extra=["nope"]), "without an annotation"),
        (lambda d: d["annotations"][1].update(frame_dir="S001C001P001R001A001"), "appears twice"),
        (lambda d: d["annotations"][0].update(keypoint=np.zeros((1, 20, 25, 2))), "keypoint_score"),
        (lambda d: d.pop("split"), "'split' and 'annotations'"),
    ],
)
def test_annotation_structure_errors(tmp_path, edit, words):
    data = _pyskl_3d()
    edit(data)
    path = tmp_path / "bad.pkl"
    path.write_bytes(pickle.dumps(data))
    with pytest.raises(AnnotationFileError) as info:
        load_annotations(path)
    assert str(path) in str(info.value) and words in str(info.value)


def test_save_annotations_is_atomic(tmp_path):
    out = tmp_path / "sub" / "anno.pkl"
    save_annotations(_pyskl_3d(), out)
    assert load_annotations(out)["annotations"][0]["frame_dir"] == "S001C001P001R001A001"
    before = out.read_bytes()
    broken = _pyskl_3d()
    broken["annotations"][0]["keypoint"] = "not an array"
    with pytest.raises(AnnotationFileError):
        save_annotations(broken, out)
    assert out.read_bytes() == before and sorted(p.name for p in out.parent.iterdir()) == ["anno.pkl"]


def test_prepare_float16_as_pyskl(raw_folder, tmp_path):
    """``--dtype float16`` stores the keypoints as PYSKL's ntu_preproc.py does; float32 is the default."""
    out16, out32 = tmp_path / "ntu60_fp16.pkl", tmp_path / "ntu60_fp32.pkl"
    common = ["prepare", "ntu60", "--raw", str(raw_folder), "--workers", "1"]
    assert sm_main([*common, "--out", str(out16), "--dtype", "float16"]) == 0
    assert sm_main([*common, "--out", str(out32)]) == 0
    with open(out16, "rb") as f:  # our own file, just written
        raw16 = pickle.load(f)
    with open(out32, "rb") as f:
        raw32 = pickle.load(f)
    assert {a["keypoint"].dtype for a in raw16["annotations"]} == {np.dtype(np.float16)}
    assert {a["keypoint"].dtype for a in raw32["annotations"]} == {np.dtype(np.float32)}
    for a16, a32 in zip(raw16["annotations"], raw32["annotations"], strict=True):
        np.testing.assert_array_equal(a16["keypoint"], a32["keypoint"].astype(np.float16))
    assert load_annotations(out16)["annotations"][0]["keypoint"].dtype == np.float32  # read back as float32


def test_float16_overflow_is_refused(tmp_path):
    data = {"split": {"a": ["x"]}, "annotations": [
        {"frame_dir": "x", "label": 0, "total_frames": 1, "keypoint": np.full((1, 1, 25, 3), 7e4, np.float32)}
    ]}  # fmt: skip
    with pytest.raises(AnnotationFileError, match="x: keypoint exceeds the float16 range"):
        save_annotations(data, tmp_path / "big.pkl", keypoint_dtype="float16")
    assert not (tmp_path / "big.pkl").exists()
