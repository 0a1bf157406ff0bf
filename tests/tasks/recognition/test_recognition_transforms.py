"""Recognition pre-processing: PYSKL PreNormalize3D/2D, UniformSample, rotation/scale, the pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.formats.ntu import read_skeleton_file
from skeleton_mamba.tasks.recognition.transforms import (
    SkeletonPipeline,
    keep_bodies,
    pre_normalize_2d,
    pre_normalize_3d,
    random_rotate_scale,
    uniform_sample_indices,
)
from tests.tasks.recognition.cases import moved_person, pyskl_test_indices

# NTU bones, 1-based child -> parent (reference section 1.3)
BONES = [(1, 2), (2, 21), (3, 21), (4, 3), (5, 21), (6, 5), (7, 6), (8, 7), (9, 21), (10, 9), (11, 10),
         (12, 11), (13, 1), (14, 13), (15, 14), (16, 15), (17, 1), (18, 17), (19, 18), (20, 19), (22, 23),
         (23, 8), (24, 25), (25, 12)]  # fmt: skip


def angle(u: np.ndarray, v: np.ndarray) -> float:
    return float(np.arccos(np.clip(np.dot(u, v) / np.linalg.norm(u) / np.linalg.norm(v), -1, 1)))


def bone_lengths(kp: np.ndarray) -> np.ndarray:
    return np.stack([np.linalg.norm(kp[..., c - 1, :] - kp[..., p - 1, :], axis=-1) for c, p in BONES], -1)


def test_pre_normalize_3d_aligns_spine_and_shoulders():
    person = moved_person(5, seed=0)  # template: shoulders (joints 9, 5) perpendicular to the spine (1 -> 2)
    out = pre_normalize_3d(person[None])
    assert out.shape == (1, 5, 25, 3) and out.dtype == np.float32
    np.testing.assert_allclose(out[0, 0, 1], 0.0, atol=1e-6)  # centred on joint 2 of frame 0
    assert angle(out[0, 0, 1] - out[0, 0, 0], np.array([0, 0, 1.0])) < 1e-5  # spine along +z
    assert angle(out[0, 0, 8] - out[0, 0, 4], np.array([1.0, 0, 0])) < 1e-5  # right - left shoulder along +x
    np.testing.assert_allclose(bone_lengths(out[0]), bone_lengths(person), atol=1e-5)  # rigid


def test_pre_normalize_3d_generic_body_and_two_people():
    person = moved_person(6, seed=1)
    person[:, 8] += [0.0, 0.1, 0.05]  # shoulders no longer perpendicular to the spine
    other = moved_person(6, seed=2)
    keypoint = np.stack([person, other])
    keypoint[0, :2] = 0  # the first person is absent in frames 0-1, the second is there throughout
    keypoint[1, 3, 7] = 0  # an untracked joint stays zero
    out = pre_normalize_3d(keypoint)
    assert out.shape == (2, 6, 25, 3)  # the second person has more frames and becomes the main body
    np.testing.assert_allclose(out[0, 0, 1], 0.0, atol=1e-6)
    assert angle(out[0, 0, 8] - out[0, 0, 4], np.array([1.0, 0, 0])) < 1e-5
    assert not out[0, 3, 7].any() and not out[1, :2].any()
    np.testing.assert_allclose(bone_lengths(out[1, 2:]), bone_lengths(person[2:]), atol=1e-5)
    # the main body decides which frames are kept
    single = np.stack([person, other])
    single[0, 4:] = 0
    single[1, :1] = 0
    assert pre_normalize_3d(single).shape[1] == 5
    assert not pre_normalize_3d(np.zeros((1, 3, 25, 3))).any()


def test_pre_normalize_3d_on_the_real_sample(shared_data):
    kp = read_skeleton_file(shared_data / "ntu" / "S001C001P001R001A001.skeleton").keypoints()
    out = pre_normalize_3d(kp)
    assert out.shape == kp.shape
    np.testing.assert_allclose(out[0, 0, 1], 0.0, atol=1e-6)
    assert angle(out[0, 0, 8] - out[0, 0, 4], np.array([1.0, 0, 0])) < 1e-5
    np.testing.assert_allclose(bone_lengths(out[0]), bone_lengths(kp[0]), atol=1e-5)


def test_pre_normalize_2d_hand_values():
    kp = np.array([[[[960.0, 540.0], [1920.0, 0.0], [0.0, 1080.0], [480.0, 270.0]]]])
    score = np.array([[[0.9, 0.9, 0.9, 0.0]]])
    out = pre_normalize_2d(kp, score, img_shape=(1080, 1920))
    np.testing.assert_allclose(out[0, 0], [[0, 0], [1, -1], [-1, 1], [0, 0]])  # the last one has score 0
    np.testing.assert_allclose(pre_normalize_2d(np.full((1, 1, 1, 2), 0.25), img_shape=(1, 1)), -0.5)


@pytest.mark.parametrize("total", [1, 7, 30, 100, 150, 199, 250, 600])
def test_uniform_sample_test_mode_matches_pyskl(total):
    a = uniform_sample_indices(total, 100, 10, test_mode=True, rng=np.random.default_rng(1))
    b = uniform_sample_indices(total, 100, 10, test_mode=True, rng=np.random.default_rng(2))
    np.testing.assert_array_equal(a, b)  # deterministic, whatever generator is passed
    assert a.shape == (1000,) and a.min() >= 0 and a.max() < total
    np.testing.assert_array_equal(a, pyskl_test_indices(total, 100, 10))


def test_uniform_sample_train_mode_segments():
    rng = np.random.default_rng(0)
    for _ in range(20):
        inds = uniform_sample_indices(250, 100, 1, rng=rng)  # T >= 2 * clip_len: one frame per segment
        bounds = np.array([k * 250 // 100 for k in range(101)])
        assert np.all((inds >= bounds[:-1]) & (inds < bounds[1:]))
        mid = uniform_sample_indices(150, 100, 1, rng=rng)  # clip_len <= T < 2 clip_len: increasing
        assert np.all(np.diff(mid) >= 1) and mid.min() >= 0 and mid.max() < 150
        short = uniform_sample_indices(30, 100, 2, rng=rng)  # T < clip_len: a looped run of frames
        assert np.all(np.diff(short.reshape(2, 100), axis=1) % 30 == 1)
    draws = {tuple(uniform_sample_indices(250, 100, rng=rng)) for _ in range(3)}
    assert len(draws) == 3


def test_random_rotation_preserves_bones_and_scale_is_per_axis():
    rng = np.random.default_rng(0)
    kp = np.stack([moved_person(4, seed=3), np.zeros((4, 25, 3))]).astype(np.float32)
    rotated = random_rotate_scale(kp, rng, max_angle=0.3, scale_range=0.0)
    np.testing.assert_allclose(bone_lengths(rotated[0]), bone_lengths(kp[0]), atol=1e-5)
    assert not rotated[1].any() and not np.allclose(rotated[0], kp[0])
    # each angle is at most 0.3 rad, so the composed rotation turns any vector by at most 3 * 0.3 rad
    assert angle(rotated[0, 0, 1] - rotated[0, 0, 0], kp[0, 0, 1] - kp[0, 0, 0]) <= 0.9
    scaled = random_rotate_scale(kp, rng, max_angle=0.0, scale_range=0.2)
    ratio = scaled[0] / kp[0]
    per_axis = ratio.reshape(-1, 3)[0]
    np.testing.assert_allclose(ratio, np.broadcast_to(per_axis, ratio.shape), rtol=1e-5)
    assert np.all((per_axis >= 0.8) & (per_axis <= 1.2))
    flat = random_rotate_scale(kp[..., :2], rng, max_angle=0.3)
    norms = np.linalg.norm(kp[0, ..., :2], axis=-1)
    np.testing.assert_allclose(np.linalg.norm(flat[0], axis=-1), norms, rtol=1e-5)


def test_keep_bodies_pads_and_truncates():
    kp = np.ones((3, 2, 25, 3), np.float32)
    assert keep_bodies(kp, 2).shape == (2, 2, 25, 3)
    padded = keep_bodies(kp[:1], 2)
    assert padded.shape == (2, 2, 25, 3) and padded[0].all() and not padded[1].any()


def test_pipeline_multi_clip_test_output():
    person = moved_person(40, seed=4)
    anno = {"frame_dir": "S001C001P001R001A001", "label": 0, "keypoint": person[None].astype(np.float32),
            "total_frames": 40}  # fmt: skip
    pipe = SkeletonPipeline(clip_len=16, num_clips=10, test_mode=True)
    out = pipe(anno)
    assert out.shape == (10, 2, 16, 25, 3) and out.dtype == np.float32
    np.testing.assert_array_equal(out, pipe(anno))
    expected = pre_normalize_3d(anno["keypoint"])[0, pyskl_test_indices(40, 16, 10)].reshape(10, 16, 25, 3)
    np.testing.assert_allclose(out[:, 0], expected, atol=1e-6)
    assert not out[:, 1].any()  # the second body slot is zero padding
    train = SkeletonPipeline(clip_len=16, max_angle=0.3)(anno, np.random.default_rng(0))
    assert train.shape == (1, 2, 16, 25, 3)
    np.testing.assert_allclose(bone_lengths(train[0, 0]), bone_lengths(person[:16]), atol=1e-5)


def test_pipeline_2d_appends_scores():
    rng = np.random.default_rng(0)
    kp = rng.uniform(0, 1, (1, 12, 18, 2)).astype(np.float32)
    score = rng.uniform(0.1, 1, (1, 12, 18)).astype(np.float32)
    anno = {"frame_dir": "clip", "label": 3, "keypoint": kp, "keypoint_score": score, "total_frames": 12,
            "img_shape": (1, 1)}  # fmt: skip
    out = SkeletonPipeline(clip_len=8, num_clips=2, test_mode=True)(anno)
    assert out.shape == (2, 2, 8, 18, 3)
    inds = pyskl_test_indices(12, 8, 2).reshape(2, 8)
    np.testing.assert_allclose(out[:, 0, :, :, :2], 2 * kp[0, inds] - 1, atol=1e-6)
    np.testing.assert_allclose(out[:, 0, :, :, 2], score[0, inds])


def _pyskl_random_scale_rot(random, skeleton: np.ndarray, theta: float, scale: float) -> np.ndarray:
    """PYSKL pose_related.py RandomScale then RandomRot, transcribed with its explicit matrices.

    ``random`` stands for PYSKL's global ``np.random`` (a ``RandomState`` seeded like it).
    """
    c = skeleton.shape[-1]
    skeleton = skeleton * (1 + random.uniform(-1, 1, size=c) * np.array((scale,) * c))
    if np.all(np.isclose(skeleton, 0)):
        return skeleton
    if c == 3:
        t = random.uniform(-theta, theta, size=3)
        cos, sin = np.cos(t), np.sin(t)
        rx = np.array([[1, 0, 0], [0, cos[0], sin[0]], [0, -sin[0], cos[0]]])
        ry = np.array([[cos[1], 0, -sin[1]], [0, 1, 0], [sin[1], 0, cos[1]]])
        rz = np.array([[cos[2], sin[2], 0], [-sin[2], cos[2], 0], [0, 0, 1]])
        rot = rz @ ry @ rx
    else:
        t = random.uniform(-theta)
        rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    return np.einsum("ab,mtvb->mtva", rot, skeleton)


@pytest.mark.parametrize("c", [3, 2])
def test_random_rotate_scale_is_pyskl_draw_for_draw(c):
    kp = np.stack([moved_person(4, seed=5), moved_person(4, seed=6)]).astype(np.float32)[..., :c]
    zeros = np.zeros_like(kp)
    ours_rng, pyskl_rng = np.random.RandomState(7), np.random.RandomState(7)
    for sample in (kp, zeros, kp, kp):  # an all-zero sample draws no angle in PYSKL: the streams stay aligned
        expected = _pyskl_random_scale_rot(pyskl_rng, sample.astype(np.float64), 0.3, 0.1)
        ours = random_rotate_scale(sample, ours_rng, max_angle=0.3, scale_range=0.1)
        np.testing.assert_allclose(ours, expected, rtol=1e-5, atol=1e-5)
    # PYSKL's 2-D angle is uniform on [-theta, 1): over many draws some exceed theta
    rng = np.random.RandomState(0)
    unit = np.zeros((1, 1, 1, 2), np.float32)
    unit[..., 0] = 1.0
    angles = [np.arctan2(*random_rotate_scale(unit, rng, 0.3)[0, 0, 0, ::-1]) for _ in range(200)]
    assert max(angles) > 0.9 and min(angles) >= -0.3 - 1e-6
