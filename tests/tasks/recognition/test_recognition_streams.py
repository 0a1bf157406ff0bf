"""Recognition input streams: [PYSKL] ``GenSkeFeat`` joint / bone / joint-motion / bone-motion features.

The reference below is written from PYSKL's rule (pyskl/datasets/pipelines/pose_related.py ``JointToBone``,
``ToMotion``, ``MergeSkeFeat``) with plain loops in float64, independently of the library code.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from skeleton_mamba.errors import CheckpointError, InputError
from skeleton_mamba.tasks.recognition import module as module_file
from skeleton_mamba.tasks.recognition.data import SyntheticRecognitionDataModule
from skeleton_mamba.tasks.recognition.module import ActionRecognitionModule
from skeleton_mamba.tasks.recognition.transforms import (
    BONE_PAIRS,
    SkeletonPipeline,
    pre_normalize_2d,
    pre_normalize_3d,
    random_rotate_scale,
    skeleton_features,
    uniform_sample_indices,
)
from tests.tasks.recognition.cases import TINY, moved_person, pyskl_test_indices

# PYSKL JointToBone.pairs per layout ('nturgb+d', 'openpose', 'coco'), 0-based (v1, v2): bone v1 = v1 - v2
PYSKL_PAIRS = {
    "ntu25": ((0, 1), (1, 20), (2, 20), (3, 2), (4, 20), (5, 4), (6, 5), (7, 6), (8, 20), (9, 8), (10, 9),
              (11, 10), (12, 0), (13, 12), (14, 13), (15, 14), (16, 0), (17, 16), (18, 17), (19, 18),
              (21, 22), (20, 20), (22, 7), (23, 24), (24, 11)),
    "openpose18": ((0, 0), (1, 0), (2, 1), (3, 2), (4, 3), (5, 1), (6, 5), (7, 6), (8, 2), (9, 8), (10, 9),
                   (11, 5), (12, 11), (13, 12), (14, 0), (15, 0), (16, 14), (17, 15)),
    "coco17": ((0, 0), (1, 0), (2, 0), (3, 1), (4, 2), (5, 0), (6, 0), (7, 5), (8, 6), (9, 7), (10, 8),
               (11, 0), (12, 0), (13, 11), (14, 12), (15, 13), (16, 14)),
}  # fmt: skip
TWO_D = {"openpose18", "coco17"}  # PYSKL: dataset in ['openpose', 'coco'] with C == 3 -> channel 2 is a score


def reference_bone(x: np.ndarray, layout: str) -> np.ndarray:
    m_, t_, v_, c_ = x.shape
    score = c_ == 3 and layout in TWO_D
    out = np.zeros((m_, t_, v_, c_))
    for v1, v2 in PYSKL_PAIRS[layout]:
        for m in range(m_):
            for t in range(t_):
                for c in range(c_):
                    if score and c == 2:
                        out[m, t, v1, c] = (x[m, t, v1, c] + x[m, t, v2, c]) / 2
                    else:
                        out[m, t, v1, c] = x[m, t, v1, c] - x[m, t, v2, c]
    return out


def reference_motion(x: np.ndarray, layout: str) -> np.ndarray:
    m_, t_, v_, c_ = x.shape
    score = c_ == 3 and layout in TWO_D
    out = np.zeros((m_, t_, v_, c_))  # the last frame stays zero
    for m in range(m_):
        for t in range(t_ - 1):
            for v in range(v_):
                for c in range(c_):
                    if score and c == 2:
                        out[m, t, v, c] = (x[m, t, v, c] + x[m, t + 1, v, c]) / 2
                    else:
                        out[m, t, v, c] = x[m, t + 1, v, c] - x[m, t, v, c]
    return out


def reference_features(keypoint: np.ndarray, feats: list[str], layout: str) -> np.ndarray:
    j = np.asarray(keypoint, dtype=np.float64)
    b = reference_bone(j, layout)
    made = {"j": j, "b": b, "jm": reference_motion(j, layout), "bm": reference_motion(b, layout)}
    return np.concatenate([made[f] for f in feats], axis=-1)


def two_bodies(layout: str, frames: int = 6, seed: int = 0) -> np.ndarray:
    """(2, frames, V, C): random joints (x, y, score in [0, 1] for 2-D layouts); body 1 missing in frame 2."""
    rng = np.random.default_rng(seed)
    v = len(PYSKL_PAIRS[layout])
    keypoint = rng.normal(size=(2, frames, v, 3))
    if layout in TWO_D:
        keypoint[..., 2] = rng.uniform(0.1, 1.0, size=(2, frames, v))
    keypoint[1, 2] = 0.0
    return keypoint.astype(np.float32)


FEATS = [["j"], ["b"], ["jm"], ["bm"], ["j", "b", "jm", "bm"], ["bm", "j"]]


def test_the_bone_pairs_are_pyskls():
    assert {k: tuple(v) for k, v in BONE_PAIRS.items()} == PYSKL_PAIRS
    for layout, pairs in PYSKL_PAIRS.items():  # every joint has exactly one bone
        assert sorted(v1 for v1, _ in pairs) == list(range(len(pairs))), layout


@pytest.mark.parametrize("feats", FEATS, ids="+".join)
@pytest.mark.parametrize("layout", ["ntu25", "openpose18", "coco17"])
def test_features_equal_pyskls_rule_in_float64(layout, feats):
    keypoint = two_bodies(layout)
    got = skeleton_features(keypoint, feats, layout)
    assert got.dtype == np.float32 and got.shape == (2, 6, keypoint.shape[2], 3 * len(feats))
    np.testing.assert_allclose(got, reference_features(keypoint, feats, layout), rtol=1e-6, atol=1e-6)
    for i, feat in enumerate(feats):
        if feat in ("jm", "bm"):  # PYSKL ToMotion: the last frame's motion is zero, score channel included
            assert not got[:, -1, :, 3 * i : 3 * i + 3].any()


def test_two_dimensional_features_keep_the_score_out_of_the_differences():
    keypoint = two_bodies("openpose18")
    out = skeleton_features(keypoint, ["b", "jm"], "openpose18")
    # joint 3's bone starts at joint 2: x, y differenced, the score averaged
    np.testing.assert_allclose(out[0, 0, 3, :2], keypoint[0, 0, 3, :2] - keypoint[0, 0, 2, :2], rtol=1e-6)
    assert out[0, 0, 3, 2] == pytest.approx((keypoint[0, 0, 3, 2] + keypoint[0, 0, 2, 2]) / 2)
    assert out[0, 1, 5, 5] == pytest.approx((keypoint[0, 1, 5, 2] + keypoint[0, 2, 5, 2]) / 2)
    xy = keypoint[..., :2]  # x, y alone (C = 2): every channel is a coordinate
    np.testing.assert_allclose(
        skeleton_features(xy, ["b", "bm"], "openpose18"), reference_features(xy, ["b", "bm"], "openpose18"),
        rtol=1e-6, atol=1e-6,
    )  # fmt: skip


def _annotation_3d(frames: int = 40) -> dict:
    keypoint = np.stack([moved_person(frames, seed=4), moved_person(frames, seed=5)]).astype(np.float32)
    return {"frame_dir": "S001C001P001R001A001", "label": 0, "keypoint": keypoint, "total_frames": frames}


def test_pipeline_computes_the_features_on_the_whole_sequence_then_samples():
    anno, feats = _annotation_3d(), ["j", "b", "jm", "bm"]
    out = SkeletonPipeline(clip_len=16, num_clips=3, test_mode=True, feats=feats, skeleton="ntu25")(anno)
    assert out.shape == (3, 2, 16, 25, 12)
    full = reference_features(pre_normalize_3d(anno["keypoint"]), feats, "ntu25")
    expected = full[:, pyskl_test_indices(40, 16, 3)].reshape(2, 3, 16, 25, 12).transpose(1, 0, 2, 3, 4)
    np.testing.assert_allclose(out, expected, atol=1e-5)


def test_pipeline_two_dimensional_features():
    rng = np.random.default_rng(1)
    kp = rng.uniform(0, 1, (2, 12, 18, 2)).astype(np.float32)
    score = rng.uniform(0.1, 1, (2, 12, 18)).astype(np.float32)
    anno = {"frame_dir": "clip", "label": 3, "keypoint": kp, "keypoint_score": score, "total_frames": 12,
            "img_shape": (1, 1)}  # fmt: skip
    out = SkeletonPipeline(8, 2, True, feats=["jm", "b"], skeleton="openpose18")(anno)
    joints = np.concatenate([pre_normalize_2d(kp, score, (1, 1)), score[..., None]], axis=-1)
    full = reference_features(joints, ["jm", "b"], "openpose18")
    expected = full[:, pyskl_test_indices(12, 8, 2)].reshape(2, 2, 8, 18, 6).transpose(1, 0, 2, 3, 4)
    np.testing.assert_allclose(out, expected, atol=1e-5)


@pytest.mark.parametrize("before", [True, False], ids=["augment_then_sample", "sample_then_augment"])
def test_training_augmentation_turns_every_feature_alike(before):
    anno = _annotation_3d(30)
    pipe = SkeletonPipeline(16, max_angle=0.3, scale_range=0.1, augment_before_sampling=before,
                            feats=["j", "b"], skeleton="ntu25")  # fmt: skip
    out = pipe(anno, np.random.RandomState(3))[0]
    rng, joints = np.random.RandomState(3), pre_normalize_3d(anno["keypoint"])
    if before:  # PYSKL: RandomScale, RandomRot, GenSkeFeat, UniformSample
        joints = random_rotate_scale(joints, rng, 0.3, 0.1)
        inds = uniform_sample_indices(30, 16, 1, False, rng)
        expected = reference_features(joints, ["j", "b"], "ntu25")[:, inds]
    else:  # sampled first; one scale and rotation for the joints and the bones
        inds = uniform_sample_indices(30, 16, 1, False, rng)
        turned = random_rotate_scale(joints[:, inds], rng, 0.3, 0.1)
        expected = reference_features(turned, ["j", "b"], "ntu25")
    np.testing.assert_allclose(out, expected, atol=1e-5)


@pytest.mark.parametrize("skeleton", ["ntu25", "openpose18"])
def test_the_data_option_sets_the_channels(skeleton):
    for feats, channels in ((["j"], 3), (["bm"], 3), (["j", "b", "jm", "bm"], 12)):
        dm = SyntheticRecognitionDataModule(skeleton=skeleton, feats=feats, train_per_class=1)
        assert dm.in_channels == dm.contract.in_channels == channels
    dm.setup("fit")
    keypoint, _ = dm.datasets["train"][0]
    assert keypoint.shape[-1] == 12
    with pytest.raises(InputError, match="names a feature twice"):
        SyntheticRecognitionDataModule(feats=["b", "b"])
    with pytest.raises(InputError, match="no PYSKL bone pairs for skeleton 'smpl24'"):
        SyntheticRecognitionDataModule(feats=["b"], skeleton="smpl24")


def test_a_checkpoint_of_another_stream_is_refused(monkeypatch):
    module = ActionRecognitionModule(backbone=TINY, num_classes=3)
    trainer = SimpleNamespace(datamodule=SimpleNamespace(feats=("j",)))
    monkeypatch.setattr(module_file, "attached_trainer", lambda _: trainer)
    saved = {"skeleton": "ntu25", "feats": ["b"]}
    with pytest.raises(CheckpointError, match=r"trained on feats \['b'\].*--data.init_args.feats '\[b\]'"):
        module.on_load_checkpoint({"datamodule_hyper_parameters": saved})
    module.on_load_checkpoint({"datamodule_hyper_parameters": {"skeleton": "ntu25"}})  # older: joints
    module.on_load_checkpoint({})  # no data module saved: nothing to compare
