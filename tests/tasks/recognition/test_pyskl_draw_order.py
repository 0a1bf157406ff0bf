"""[PYSKL] random draws: RandomScale / RandomRot / UniformSampleFrames, draw for draw and in PYSKL's order.

The reference is a transcription, written here, of PYSKL's pyskl/datasets/pipelines (pose_related.py
``RandomScale``, ``RandomRot``, ``PoseDecode``, ``FormatGCNInput``; sampling.py ``UniformSampleFrames``
training clips) drawing from numpy's global generator after ``np.random.seed(seed)``, as PYSKL does. Ours
get ``np.random.RandomState(seed)``. A transform that a config leaves out draws nothing, so the settings
(scale only, rotation only, both, neither; 2-D and 3-D) each have their own draw sequence. PYSKL's
strong-augmentation configs (configs/strong_aug/*/j.py: PreNormalize3D, RandomScale(scale=0.1), RandomRot(),
GenSkeFeat, UniformSample(clip_len=100), PoseDecode, FormatGCNInput(num_person=2)) augment the whole
sequence before sampling. The normalisation stage is ours (``pre_normalize_3d`` / ``pre_normalize_2d``,
compared with PYSKL in test_recognition_transforms.py); what is tested here is what comes after it.
"""

# ruff: noqa: NPY002 -- the reference draws from numpy's legacy global generator, as PYSKL does
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from skeleton_mamba.tasks.motion.formats.ntu import read_skeleton_file
from skeleton_mamba.tasks.recognition.data import RecognitionDataModule, SyntheticRecognitionDataModule
from skeleton_mamba.tasks.recognition.transforms import (
    SkeletonPipeline,
    pre_normalize_2d,
    pre_normalize_3d,
    random_rotate_scale,
)

RECIPES = Path(__file__).resolve().parents[3] / "recipes"

# (scale, theta) of the PYSKL transforms in the pipeline; None: the transform is not in the config.
SETTINGS = {"neither": (None, None), "scale": (0.1, None), "rotate": (None, 0.3), "both": (0.1, 0.3)}


@pytest.fixture(autouse=True)
def _keep_global_random_state():
    """The transcription seeds numpy's global generator (as PYSKL does); leave it as it was."""
    state = np.random.get_state()
    yield
    np.random.set_state(state)


# ---- the transcription of PYSKL (global np.random) ----------------------------------------------------


def pyskl_random_scale(skeleton: np.ndarray, scale: float) -> np.ndarray:
    """RandomScale.__call__ with a float ``scale``: C factors, drawn whatever ``scale`` is."""
    scales = (scale,) * skeleton.shape[-1]
    factors = 1 + np.random.uniform(-1, 1, size=len(scales)) * np.array(scales)
    return skeleton * factors


def pyskl_random_rot(skeleton: np.ndarray, theta: float) -> np.ndarray:
    """RandomRot.__call__: nothing drawn for an all-zero sample; 3 angles for C = 3, one for C = 2."""
    if np.all(np.isclose(skeleton, 0)):
        return skeleton
    if skeleton.shape[-1] == 3:
        t = np.random.uniform(-theta, theta, size=3)
        cos, sin = np.cos(t), np.sin(t)
        rx = np.array([[1, 0, 0], [0, cos[0], sin[0]], [0, -sin[0], cos[0]]])
        ry = np.array([[cos[1], 0, -sin[1]], [0, 1, 0], [sin[1], 0, cos[1]]])
        rz = np.array([[cos[2], sin[2], 0], [-sin[2], cos[2], 0], [0, 0, 1]])
        rot = np.matmul(rz, np.matmul(ry, rx))
    else:
        t = np.random.uniform(-theta)  # numpy's high defaults to 1.0: PYSKL's 2-D range is [-theta, 1)
        rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    return np.einsum("ab,mtvb->mtva", rot, skeleton)


def pyskl_train_indices(num_frames: int, clip_len: int, num_clips: int = 1) -> np.ndarray:
    """UniformSampleFrames._get_train_clips (p_interval 1) followed by the np.mod of __call__."""
    allinds = []
    for _ in range(num_clips):
        old_num_frames = num_frames
        ratio = np.random.rand() * (1 - 1) + 1
        num_frames = int(ratio * num_frames)
        off = np.random.randint(old_num_frames - num_frames + 1)
        if num_frames < clip_len:
            start = np.random.randint(0, num_frames)
            inds = np.arange(start, start + clip_len)
        elif clip_len <= num_frames < 2 * clip_len:
            basic = np.arange(clip_len)
            inds = np.random.choice(clip_len + 1, num_frames - clip_len, replace=False)
            offset = np.zeros(clip_len + 1, dtype=np.int64)
            offset[inds] = 1
            inds = basic + np.cumsum(offset)[:-1]
        else:
            bids = np.array([i * num_frames // clip_len for i in range(clip_len + 1)])
            inds = bids[:clip_len] + np.random.randint(np.diff(bids))
        allinds.append(inds + off)
        num_frames = old_num_frames
    return np.mod(np.concatenate(allinds), num_frames)


def pyskl_format_gcn_input(keypoint: np.ndarray, num_person: int, num_clips: int) -> np.ndarray:
    """FormatGCNInput(mode='zero'): (M, nc * T, V, C) -> (nc, num_person, T, V, C)."""
    if keypoint.shape[0] < num_person:
        pad = np.zeros((num_person - keypoint.shape[0],) + keypoint.shape[1:], dtype=keypoint.dtype)
        keypoint = np.concatenate((keypoint, pad), axis=0)
    keypoint = keypoint[:num_person]
    m, t, v, c = keypoint.shape
    return keypoint.reshape((m, num_clips, t // num_clips, v, c)).transpose(1, 0, 2, 3, 4)


def pyskl_train_pipeline(
    keypoint: np.ndarray, score, scale, theta, clip_len: int, num_person: int, sample_first: bool = False
) -> np.ndarray:
    """[RandomScale(scale)] -> [RandomRot(theta)] -> GenSkeFeat -> UniformSample -> PoseDecode -> Format.

    ``keypoint``: (M, T, V, 2 or 3) after PreNormalize; ``score``: (M, T, V) or None (appended as a channel,
    GenSkeFeat). ``sample_first``: the other order, sampling draws first, the transforms on the clip.
    """
    keypoint = keypoint.astype(np.float64)

    def augment(kp):
        if scale is not None:
            kp = pyskl_random_scale(kp, scale)
        if theta is not None:
            kp = pyskl_random_rot(kp, theta)
        return kp

    if sample_first:
        inds = pyskl_train_indices(keypoint.shape[1], clip_len)
        keypoint = augment(keypoint[:, inds])
        score = None if score is None else score[:, inds]
    else:
        keypoint = augment(keypoint)
        inds = pyskl_train_indices(keypoint.shape[1], clip_len)
        keypoint = keypoint[:, inds]
        score = None if score is None else score[:, inds]
    if score is not None:
        keypoint = np.concatenate([keypoint, score[..., None]], -1)
    return pyskl_format_gcn_input(keypoint.astype(np.float32), num_person, 1)


# ---- samples ---------------------------------------------------------------------------------------------


def person(frames: int, seed: int) -> np.ndarray:
    """(frames, 25, 3): a random rigid body (joints spread over ~1 m), rotated, translated and drifting."""
    rng = np.random.default_rng(seed)
    body = rng.normal(0, 0.4, (25, 3))
    body = body @ Rotation.random(random_state=seed).as_matrix().T + rng.uniform(-2, 2, 3)
    return body[None] + 0.02 * rng.normal(size=(frames, 1, 3)).cumsum(0)


def ntu_annotation(frames: int, bodies: int, seed: int) -> dict:
    """A 3-D annotation; the second body (if any) is absent for the first third of the frames."""
    kp = np.stack([person(frames, seed + i) for i in range(bodies)]).astype(np.float32)
    if bodies > 1:
        kp[1, : frames // 3] = 0
    return {"frame_dir": f"s{seed}", "label": 0, "keypoint": kp, "total_frames": frames}


def kinetics_annotation(frames: int, seed: int) -> dict:
    """A 2-D annotation (2 bodies, pixel x y in a 340 x 256 frame, scores in (0.05, 1])."""
    rng = np.random.default_rng(seed)
    kp = rng.uniform(0, 1, (2, frames, 18, 2)) * [340, 256]
    score = rng.uniform(0.05, 1, (2, frames, 18))
    kp, score = kp.astype(np.float32), score.astype(np.float32)
    return {"frame_dir": f"k{seed}", "label": 0, "keypoint": kp, "keypoint_score": score,
            "img_shape": (256, 340), "total_frames": frames}  # fmt: skip


def off_to_zero(value):
    """Our spelling of a transform left out of the pipeline: range 0 (the pipeline's convention)."""
    return 0.0 if value is None else value


# ---- the augmentations alone ----------------------------------------------------------------------------


@pytest.mark.parametrize("setting", list(SETTINGS))
@pytest.mark.parametrize("c", [3, 2])
@pytest.mark.parametrize("seed", [0, 1, 2024])
def test_random_rotate_scale_draws_as_pyskl(setting, c, seed):
    """Several samples in a row (one all zero, which draws no angle) from one stream; then the next draw."""
    scale, theta = SETTINGS[setting]
    kp = ntu_annotation(12, 2, seed)["keypoint"][..., :c]
    samples = [kp, np.zeros_like(kp), 0.5 * kp, kp[:, ::-1]]
    np.random.seed(seed)
    expected = []
    for sample in samples:
        out = sample.astype(np.float64)
        if scale is not None:
            out = pyskl_random_scale(out, scale)
        if theta is not None:
            out = pyskl_random_rot(out, theta)
        expected.append(out)
    rng = np.random.RandomState(seed)
    for sample, want in zip(samples, expected, strict=True):
        got = random_rotate_scale(sample, rng, off_to_zero(theta), off_to_zero(scale))
        assert got.dtype == np.float32
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    assert rng.random_sample() == np.random.random_sample()  # the same number of draws was taken


@pytest.mark.parametrize("c", [3, 2])
def test_off_is_none_or_zero(c):
    """``None`` and 0 both leave a transform out: nothing drawn, the input returned (as float32)."""
    kp = ntu_annotation(6, 1, 3)["keypoint"][..., :c]
    for off in (None, 0.0):
        rng = np.random.RandomState(5)
        np.testing.assert_array_equal(random_rotate_scale(kp, rng, off, off), kp)
        assert rng.random_sample() == np.random.RandomState(5).random_sample()


# ---- the pipeline: PYSKL's order -------------------------------------------------------------------------


@pytest.mark.parametrize("setting", list(SETTINGS))
@pytest.mark.parametrize(("frames", "bodies"), [(70, 2), (45, 1), (20, 3)])  # >= 2 clip_len, between, short
@pytest.mark.parametrize("seed", [0, 7])
def test_pipeline_3d_equals_pyskl_strong_aug_order(setting, frames, bodies, seed):
    scale, theta = SETTINGS[setting]
    anno = ntu_annotation(frames, bodies, seed)
    np.random.seed(seed)
    expected = pyskl_train_pipeline(pre_normalize_3d(anno["keypoint"]), None, scale, theta, 32, 2)
    pipe = SkeletonPipeline(
        clip_len=32, num_person=2, max_angle=off_to_zero(theta), scale_range=off_to_zero(scale)
    )
    rng = np.random.RandomState(seed)
    got = pipe(anno, rng)
    assert got.shape == expected.shape == (1, 2, 32, 25, 3)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5)
    assert rng.random_sample() == np.random.random_sample()


@pytest.mark.parametrize("setting", list(SETTINGS))
@pytest.mark.parametrize("seed", [0, 7])
def test_pipeline_2d_equals_pyskl_order(setting, seed):
    """2-D: PYSKL's RandomScale / RandomRot on the (M, T, V, 2) x, y (2 factors, 1 angle), score appended."""
    scale, theta = SETTINGS[setting]
    anno = kinetics_annotation(50, seed)
    xy = pre_normalize_2d(anno["keypoint"], anno["keypoint_score"], anno["img_shape"])
    np.random.seed(seed)
    expected = pyskl_train_pipeline(xy, anno["keypoint_score"], scale, theta, 16, 2)
    pipe = SkeletonPipeline(clip_len=16, max_angle=off_to_zero(theta), scale_range=off_to_zero(scale))
    rng = np.random.RandomState(seed)
    got = pipe(anno, rng)
    assert got.shape == (1, 2, 16, 18, 3)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5)
    assert rng.random_sample() == np.random.random_sample()


def test_pipeline_all_zero_sample_draws_no_angle():
    """An all-zero sequence: RandomScale still draws its factors, RandomRot draws nothing, then sampling."""
    anno = {
        "frame_dir": "empty",
        "label": 0,
        "keypoint": np.zeros((1, 40, 25, 3), np.float32),
        "total_frames": 40,
    }
    np.random.seed(3)
    expected = pyskl_train_pipeline(anno["keypoint"], None, 0.1, 0.3, 16, 2)
    rng = np.random.RandomState(3)
    got = SkeletonPipeline(clip_len=16, max_angle=0.3, scale_range=0.1)(anno, rng)
    np.testing.assert_array_equal(got, expected)
    assert rng.random_sample() == np.random.random_sample()


def test_pipeline_on_the_real_sample(shared_data):
    """NTU S001C001P001R001A001 (103 frames, 1 body) through configs/strong_aug/ntu60_xsub_3dkp/j.py."""
    kp = read_skeleton_file(shared_data / "ntu" / "S001C001P001R001A001.skeleton").keypoints()
    anno = {"frame_dir": "S001C001P001R001A001", "label": 0, "keypoint": kp, "total_frames": kp.shape[1]}
    for seed in (0, 1, 2):
        np.random.seed(seed)
        expected = pyskl_train_pipeline(pre_normalize_3d(kp), None, 0.1, 0.3, 100, 2)
        got = SkeletonPipeline(clip_len=100, max_angle=0.3, scale_range=0.1)(
            anno, np.random.RandomState(seed)
        )
        np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5)


def test_pipeline_sample_first_order():
    """``augment_before_sampling=False``: sampling draws first, then the transforms on the sampled clip."""
    anno = ntu_annotation(70, 2, 11)
    for seed in (0, 1):
        np.random.seed(seed)
        expected = pyskl_train_pipeline(
            pre_normalize_3d(anno["keypoint"]), None, 0.1, 0.3, 32, 2, sample_first=True
        )
        pipe = SkeletonPipeline(clip_len=32, max_angle=0.3, scale_range=0.1, augment_before_sampling=False)
        rng = np.random.RandomState(seed)
        np.testing.assert_allclose(pipe(anno, rng), expected, rtol=1e-5, atol=1e-5)
        assert rng.random_sample() == np.random.random_sample()
    # the two orders give different clips for the same seed (the rotation angles come from other draws)
    default = SkeletonPipeline(clip_len=32, max_angle=0.3, scale_range=0.1)(anno, np.random.RandomState(0))
    other = SkeletonPipeline(clip_len=32, max_angle=0.3, scale_range=0.1, augment_before_sampling=False)(
        anno, np.random.RandomState(0)
    )
    assert np.abs(default - other).max() > 0.1


def test_pipeline_test_mode_draws_nothing_from_rng():
    """Test mode: PYSKL's reseeded sampling, no augmentation; the training generator is untouched."""
    anno = ntu_annotation(70, 2, 4)
    rng = np.random.RandomState(9)
    SkeletonPipeline(clip_len=32, num_clips=3, test_mode=True, max_angle=0.3, scale_range=0.1)(anno, rng)
    assert rng.random_sample() == np.random.RandomState(9).random_sample()


# ---- the recipes name the PYSKL config they reproduce and build its train pipeline ----------------------

# the train-pipeline transforms of the PYSKL configs the recipes name (transcribed from the config files):
# (RandomScale scale, RandomRot theta, augmentation before UniformSample); None: not in the config
PYSKL_CONFIGS = {
    "configs/stgcn++/stgcn++_ntu60_xsub_3dkp/j.py": (None, None, True),
    "configs/stgcn++/stgcn++_ntu60_xview_3dkp/j.py": (None, None, True),
    "configs/stgcn++/stgcn++_ntu120_xsub_3dkp/j.py": (None, None, True),
    "configs/stgcn++/stgcn++_ntu120_xset_3dkp/j.py": (None, None, True),
    "configs/stgcn++/stgcn++_ntu60_xsub_hrnet/j.py": (None, None, True),
}
RECOGNITION_RECIPES = {
    "ntu60.yaml": "configs/stgcn++/stgcn++_ntu60_xsub_3dkp/j.py",
    "ntu60_xview.yaml": "configs/stgcn++/stgcn++_ntu60_xview_3dkp/j.py",
    "ntu120_xsub.yaml": "configs/stgcn++/stgcn++_ntu120_xsub_3dkp/j.py",
    "ntu120_xset.yaml": "configs/stgcn++/stgcn++_ntu120_xset_3dkp/j.py",
    "kinetics.yaml": "configs/stgcn++/stgcn++_ntu60_xsub_hrnet/j.py",
    "recognition_synthetic.yaml": "configs/stgcn++/stgcn++_ntu60_xsub_3dkp/j.py",
    "recognition_synthetic_causal.yaml": "configs/stgcn++/stgcn++_ntu60_xsub_3dkp/j.py",
}


def merged_data_args(name: str) -> dict:
    """The recipe's ``data`` section with its ``base`` recipes applied first (as ``sm`` merges them)."""
    recipe = yaml.safe_load((RECIPES / name).read_text())
    data = merged_data_args(recipe["base"]) if "base" in recipe else {}
    own = recipe.get("data", {})
    data["class_path"] = own.get("class_path", data.get("class_path"))
    data["init_args"] = {**data.get("init_args", {}), **own.get("init_args", {})}
    return data


@pytest.mark.parametrize("name", list(RECOGNITION_RECIPES))
def test_recipe_names_its_pyskl_config_and_builds_its_train_pipeline(name, tmp_path):
    text = (RECIPES / name).read_text()
    named = re.findall(r"PYSKL config:? (configs/\S+\.py)", text)
    assert named == [RECOGNITION_RECIPES[name]], f"{name} names {named}"
    scale, theta, before = PYSKL_CONFIGS[named[0]]
    data = merged_data_args(name)
    args = dict(data["init_args"])
    if data["class_path"].endswith("SyntheticRecognitionDataModule"):
        module = SyntheticRecognitionDataModule(**args)
    else:
        assert data["class_path"].endswith(".RecognitionDataModule")
        ann = tmp_path / "ann.pkl"
        ann.write_bytes(b"")  # only checked for existence here
        module = RecognitionDataModule(**{**args, "ann_file": str(ann)})
    pipe = module.pipeline("fit")
    assert not pipe.test_mode
    assert pipe.scale_range == off_to_zero(scale) and pipe.max_angle == off_to_zero(theta)
    assert pipe.augment_before_sampling is before
