"""The memory-mapped keypoint store of a PYSKL annotation file (one copy per machine for every rank and
loader worker): the same samples and splits as the pickle, rebuilt only when the file changes, built from
valid files only, and never removing what is not a store."""

import json
import os
import pickle

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.recognition.data import RecognitionDataModule
from skeleton_mamba.tasks.recognition.keypoint_store import KeypointStore, ensure_store, store_folder
from skeleton_mamba.tasks.recognition.pyskl import AnnotationFileError, load_annotations, save_annotations
from skeleton_mamba.tasks.recognition.synthetic import make_synthetic_annotations


def _pyskl_file(tmp_path, skeleton="ntu25", dtype="float32", bodies=2, name="anno.pkl"):
    data = make_synthetic_annotations(num_classes=3, train_per_class=4, val_per_class=2, num_frames=12,
                                      skeleton=skeleton, num_bodies=bodies)  # fmt: skip
    for i, anno in enumerate(data["annotations"]):  # samples of different lengths and body counts
        frames = 6 + i % 7
        anno["keypoint"] = anno["keypoint"][: 1 + i % bodies, :frames]
        anno["total_frames"] = frames
        if "keypoint_score" in anno:
            anno["keypoint_score"] = anno["keypoint_score"][: 1 + i % bodies, :frames]
            anno["img_shape"] = (480 + i, 640)
    return save_annotations(data, tmp_path / name, keypoint_dtype=dtype)


@pytest.mark.parametrize(("skeleton", "dtype"), [("ntu25", "float32"), ("openpose18", "float16")])
def test_the_store_holds_the_samples_and_splits_of_the_pickle(tmp_path, skeleton, dtype):
    path = _pyskl_file(tmp_path, skeleton, dtype)
    store = ensure_store(path, tmp_path / "stores")
    expected = load_annotations(path)
    assert len(store) == len(expected["annotations"]) == 18
    assert store.keypoint.dtype == np.dtype(dtype)  # PYSKL's float16 files stay half the size
    rows = sum(a["keypoint"].shape[0] * a["keypoint"].shape[1] for a in expected["annotations"])
    joints, channels = expected["annotations"][0]["keypoint"].shape[2:]
    assert (store.folder / "keypoint.bin").stat().st_size == rows * joints * channels * np.dtype(
        dtype
    ).itemsize
    for i, want in enumerate(expected["annotations"]):
        got = store.annotation(i)
        assert set(got) == {"frame_dir", "label", "total_frames", "keypoint"} | (
            {"keypoint_score", "img_shape"} if skeleton == "openpose18" else set()
        )
        assert (got["frame_dir"], got["label"], got["total_frames"]) == (
            want["frame_dir"], want["label"], want["total_frames"]
        )  # fmt: skip
        assert got["keypoint"].dtype == np.float32
        np.testing.assert_array_equal(got["keypoint"], want["keypoint"])
        if skeleton == "openpose18":
            np.testing.assert_array_equal(got["keypoint_score"], want["keypoint_score"])
            assert got["img_shape"] == want["img_shape"]
    for name, members in expected["split"].items():
        assert store.split(name).sample_names == members


def test_the_data_module_gives_the_same_clips_from_the_store_and_from_the_pickle(tmp_path):
    path = _pyskl_file(tmp_path)
    modules = [
        RecognitionDataModule(
            str(path),
            num_classes=3,
            clip_len=8,
            num_clips_test=3,
            num_workers=0,
            memory_map=mapped,
            store_dir=str(tmp_path / "stores"),
        )  # fmt: skip
        for mapped in (True, False)
    ]
    for dm in modules:
        dm.prepare_data()
        dm.setup("fit")
        dm.setup("test")
    mapped, held = (dm.datasets for dm in modules)
    assert mapped["test"].sample_names == held["test"].sample_names
    for i in range(len(held["test"])):
        torch.testing.assert_close(mapped["test"][i][0], held["test"][i][0], rtol=0, atol=0)
    torch.manual_seed(5)
    first = [mapped["train"][i] for i in range(len(mapped["train"]))]
    torch.manual_seed(5)
    second = [held["train"][i] for i in range(len(held["train"]))]
    for (a, label_a), (b, label_b) in zip(first, second, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
        assert label_a == label_b
    assert modules[0].in_channels == modules[1].in_channels == 3


def test_the_store_is_rebuilt_when_its_file_changes_and_only_then(tmp_path):
    path = _pyskl_file(tmp_path)
    store = ensure_store(path, tmp_path / "stores")
    built = (store.folder / "store.json").stat().st_mtime_ns
    assert (ensure_store(path, tmp_path / "stores").folder / "store.json").stat().st_mtime_ns == built
    data = load_annotations(path)
    data["annotations"][0]["label"] = 2
    save_annotations(data, path)
    os.utime(path, ns=(built + 10**9, built + 10**9))
    assert ensure_store(path, tmp_path / "stores").annotation(0)["label"] == 2


def test_a_bad_file_is_refused_naming_the_sample_and_leaves_no_store(tmp_path):
    data = make_synthetic_annotations(num_classes=2, train_per_class=2, val_per_class=1)
    data["annotations"][2]["keypoint"][0, 3, 4, 1] = np.nan
    path = tmp_path / "bad.pkl"
    path.write_bytes(pickle.dumps(data))
    with pytest.raises(AnnotationFileError, match=r"bad\.pkl: annotation 2 \(xsub_train_001_0000\)"):
        ensure_store(path, tmp_path / "stores")
    assert [p.name for p in (tmp_path / "stores").iterdir()] == [
        f".{store_folder(path, tmp_path / 'stores').name}.lock"
    ]


def test_samples_of_two_layouts_are_refused(tmp_path):
    data = make_synthetic_annotations(num_classes=2, train_per_class=2, val_per_class=1)
    data["annotations"][1]["keypoint"] = data["annotations"][1]["keypoint"][:, :, :20]
    path = save_annotations(data, tmp_path / "mixed.pkl")
    with pytest.raises(AnnotationFileError, match="20 joints x 3 channels, the samples before it 25 x 3"):
        ensure_store(path, tmp_path / "stores")


def test_a_folder_that_is_not_a_store_is_never_removed(tmp_path):
    path = _pyskl_file(tmp_path)
    folder = store_folder(path, tmp_path / "stores")
    folder.mkdir(parents=True)
    (folder / "store.json").write_text(json.dumps({"version": 0}))  # stale: would be rebuilt ...
    (folder / "thesis.tex").write_text("mine")  # ... but holds a file a store does not write
    with pytest.raises(AnnotationFileError, match=r"not a keypoint store \(it holds \['thesis.tex'\]\)"):
        ensure_store(path, tmp_path / "stores")
    assert (folder / "thesis.tex").read_text() == "mine"


def test_a_damaged_store_is_refused_in_one_line(tmp_path):
    store = ensure_store(_pyskl_file(tmp_path), tmp_path / "stores")
    with open(store.folder / "keypoint.bin", "r+b") as handle:
        handle.truncate(100)
    with pytest.raises(AnnotationFileError, match="not a complete keypoint store .* delete it to rebuild it"):
        KeypointStore(store.folder)


def test_the_store_pickles_as_its_folder_not_its_arrays(tmp_path):
    """A loader worker started by spawn, or a rank, maps the files itself: no keypoint is sent."""
    store = ensure_store(_pyskl_file(tmp_path), tmp_path / "stores")
    payload = pickle.dumps(store)
    assert len(payload) < 1000 < store.keypoint.nbytes
    again = pickle.loads(payload)
    np.testing.assert_array_equal(again.annotation(5)["keypoint"], store.annotation(5)["keypoint"])
