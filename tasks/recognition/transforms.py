"""Skeleton pre-processing for action recognition, following PYSKL's GCN pipeline.

Convention: PYSKL (``kennymckormick/pyskl``), the toolkit whose annotation files :mod:`.pyskl` reads and
whose ST-GCN++ / CTR-GCN configs report NTU numbers with 10-clip testing::

    PreNormalize3D (or PreNormalize2D) -> UniformSample(clip_len=100, num_clips) -> PoseDecode
        -> FormatGCNInput(num_person=2)                                   => (num_clips, M, T, V, C)

- :func:`pre_normalize_3d` = ``PreNormalize3D`` (adapted there from 2s-AGCN): keep the frames where the
  main body is present, centre on joint 2 (middle of spine; 0-based 1) of the main body in the first kept
  frame, rotate the spine (joint 1 -> 2) of that frame onto +z, then the shoulder vector right - left
  (joints 9 - 5; 0-based 8, 4) onto +x. The second rotation is about ``(r - l) x x``, so the spine stays on
  +z exactly when the shoulder line is perpendicular to it (PYSKL behaves the same).
- :func:`pre_normalize_2d` = ``PreNormalize2D``: x, y scaled to [-1, 1] by the image size.
- :func:`uniform_sample_indices` = ``UniformSampleFrames``: ``clip_len`` segments, one random frame each;
  test mode reseeds a ``RandomState(255)`` for every call, so indices match PYSKL's exactly.
- :func:`random_scale` = ``RandomScale`` and :func:`random_rot` = ``RandomRot``, draw for draw (angle signs,
  the 2-D range); :func:`random_rotate_scale` composes the two and draws only for the transforms switched on.
  PYSKL's ST-GCN++ configs use neither (the pipeline's defaults switch them off); its strong-augmentation
  configs (``configs/strong_aug/*/j.py``: ``RandomScale(scale=0.1)``, ``RandomRot()``) and DG-STGCN configs
  (``RandomRot``) put them after ``PreNormalize3D`` and *before* ``UniformSample``, which is the pipeline's
  default order (``augment_before_sampling``).
- :func:`skeleton_features` = ``GenSkeFeat(dataset, feats)``: the joint ``j``, bone ``b``, joint-motion ``jm``
  and bone-motion ``bm`` streams, alone or concatenated on the channel axis in the order given. A bone is
  the joint minus the joint its PYSKL pair names (:data:`BONE_PAIRS`, ``JointToBone``; one joint pairs with
  itself, a zero bone: NTU's spine shoulder 20, the nose 0 of OpenPose / COCO), a motion the next frame minus
  this one, zero at the last frame (``ToMotion``). For the 2-D layouts (x, y, score) the score channel is not
  differenced: a bone's score is the mean of its two joints' scores, a motion's the mean of the two frames'
  scores (zero at the last frame), as PYSKL does. PYSKL's configs run ``GenSkeFeat`` after ``PreNormalize`` /
  ``RandomScale`` / ``RandomRot`` and before ``UniformSample``, so a motion spans two consecutive frames of
  the full sequence, not of the sampled clip; the pipeline keeps that order.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "BONE_PAIRS",
    "FEATURES",
    "SCORE_LAYOUTS",
    "SkeletonPipeline",
    "check_features",
    "joint_to_bone",
    "keep_bodies",
    "pre_normalize_2d",
    "pre_normalize_3d",
    "random_rot",
    "random_rotate_scale",
    "random_scale",
    "skeleton_features",
    "to_motion",
    "uniform_sample_indices",
]

_EPS = 1e-6


def _rotation_onto(v: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(3, 3) rotation about ``v x target`` by the angle between them (identity when degenerate, as PYSKL)."""
    if np.abs(v).sum() < _EPS:
        return np.eye(3)
    axis = np.cross(v, target)
    angle = np.arccos(np.clip(np.dot(v / np.linalg.norm(v), target), -1.0, 1.0))
    if np.abs(axis).sum() < _EPS or abs(angle) < _EPS:
        return np.eye(3)
    return Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()


def pre_normalize_3d(
    keypoint: np.ndarray,
    zaxis: tuple[int, int] = (0, 1),
    xaxis: tuple[int, int] = (8, 4),
    align_center: bool = True,
    align_spine: bool = True,
) -> np.ndarray:
    """PYSKL ``PreNormalize3D`` for NTU 3D joints.

    Args:
        keypoint: (M, T, V, 3) joints; person 0 is the main body unless another has more non-empty frames.
        zaxis: 0-based (bottom, top) joints whose vector is rotated onto +z (base -> middle of spine).
        xaxis: 0-based (right, left) joints whose difference right - left is rotated onto +x (shoulders).
        align_center: subtract the main body's joint 2 (0-based 1; the last joint when V != 25) of the
            first kept frame from every non-zero joint.
        align_spine: apply the two rotations.

    Returns:
        (M, T', V, 3) float32 where T' counts the frames in which the main body is present; the main body
        comes first. An all-zero input is returned unchanged.
    """
    skeleton = np.asarray(keypoint, dtype=np.float64)
    if skeleton.ndim != 4 or skeleton.shape[-1] != 3:
        raise ValueError(f"pre_normalize_3d expects (M, T, V, 3) joints, got shape {skeleton.shape}")
    if not skeleton.any():
        return skeleton.astype(np.float32)
    present = ~np.all(np.isclose(skeleton, 0), axis=(2, 3))  # (M, T)
    main = int(np.argmax(present.sum(1)))  # PYSKL: person 1 only if it has strictly more frames
    order = [main] + [m for m in range(skeleton.shape[0]) if m != main]
    skeleton = skeleton[order][:, present[main]]
    if align_center:
        centre = skeleton[0, 0, 1 if skeleton.shape[2] == 25 else -1].copy()
        mask = (skeleton != 0).any(-1, keepdims=True)
        skeleton = (skeleton - centre) * mask
    if align_spine:
        bottom, top = skeleton[0, 0, zaxis[0]], skeleton[0, 0, zaxis[1]]
        skeleton = skeleton @ _rotation_onto(top - bottom, np.array([0.0, 0.0, 1.0])).T
        right, left = skeleton[0, 0, xaxis[0]], skeleton[0, 0, xaxis[1]]
        skeleton = skeleton @ _rotation_onto(right - left, np.array([1.0, 0.0, 0.0])).T
    return skeleton.astype(np.float32)


def pre_normalize_2d(
    keypoint: np.ndarray,
    keypoint_score: np.ndarray | None = None,
    img_shape: tuple[float, float] = (1080, 1920),
    threshold: float = 0.0,
) -> np.ndarray:
    """PYSKL ``PreNormalize2D``: map pixel coordinates to [-1, 1] by the image size.

    Args:
        keypoint: (M, T, V, 2) x, y.
        keypoint_score: optional (M, T, V) confidences; joints with score <= ``threshold`` are zeroed
            (ST-GCN zeroes joints whose OpenPose score is 0).
        img_shape: (height, width) of the frame. Use (1, 1) for coordinates already in [0, 1] (Kinetics-
            skeleton), which gives 2x - 1.

    Returns:
        (M, T, V, 2) float32 with x' = (x - w/2) / (w/2), y' = (y - h/2) / (h/2).
    """
    keypoint = np.asarray(keypoint, dtype=np.float32)
    if keypoint.ndim != 4 or keypoint.shape[-1] != 2:
        raise ValueError(f"pre_normalize_2d expects (M, T, V, 2) x, y, got shape {keypoint.shape}")
    h, w = img_shape
    out = (keypoint - np.array([w / 2, h / 2], np.float32)) / np.array([w / 2, h / 2], np.float32)
    if keypoint_score is not None:
        out[np.asarray(keypoint_score) <= threshold] = 0.0
    return out


def keep_bodies(keypoint: np.ndarray, num_person: int = 2) -> np.ndarray:
    """PYSKL ``FormatGCNInput`` person axis: keep the first ``num_person`` bodies, zero-pad to exactly that.

    Args:
        keypoint: (M, ..., C) with bodies on axis 0.

    Returns:
        (num_person, ..., C) array of the same dtype.
    """
    keypoint = np.asarray(keypoint)
    if keypoint.shape[0] >= num_person:
        return keypoint[:num_person]
    pad = np.zeros((num_person - keypoint.shape[0],) + keypoint.shape[1:], keypoint.dtype)
    return np.concatenate([keypoint, pad], axis=0)


FEATURES = ("j", "b", "jm", "bm")
"""The skeleton features of [PYSKL] ``GenSkeFeat``: joint, bone, joint motion, bone motion."""

# [PYSKL] pyskl/datasets/pipelines/pose_related.py ``JointToBone.pairs``: (joint, the joint its bone starts
# from), 0-based; every joint is the first of exactly one pair, the root paired with itself.
BONE_PAIRS: dict[str, tuple[tuple[int, int], ...]] = {
    "ntu25": (  # PYSKL 'nturgb+d' (Kinect v2 order; hand tip 21 -> thumb 22 -> hand 7, as PYSKL pairs them)
        (0, 1), (1, 20), (2, 20), (3, 2), (4, 20), (5, 4), (6, 5), (7, 6), (8, 20), (9, 8), (10, 9), (11, 10),
        (12, 0), (13, 12), (14, 13), (15, 14), (16, 0), (17, 16), (18, 17), (19, 18), (21, 22), (20, 20),
        (22, 7), (23, 24), (24, 11),
    ),
    "openpose18": (  # PYSKL 'openpose' (the ST-GCN Kinetics-skeleton order; hips pair with the shoulders)
        (0, 0), (1, 0), (2, 1), (3, 2), (4, 3), (5, 1), (6, 5), (7, 6), (8, 2), (9, 8), (10, 9), (11, 5),
        (12, 11), (13, 12), (14, 0), (15, 0), (16, 14), (17, 15),
    ),
    "coco17": (  # PYSKL 'coco' (HRNet 2-D keypoints; no skeleton of that name is registered yet)
        (0, 0), (1, 0), (2, 0), (3, 1), (4, 2), (5, 0), (6, 0), (7, 5), (8, 6), (9, 7), (10, 8), (11, 0),
        (12, 0), (13, 11), (14, 12), (15, 13), (16, 14),
    ),
}  # fmt: skip
SCORE_LAYOUTS = frozenset({"openpose18", "coco17"})
"""Layouts whose third channel, when present, is a confidence score (PYSKL's 'openpose' and 'coco')."""


def check_features(feats: Sequence[str], skeleton: str | None = None) -> tuple[str, ...]:
    """``feats`` as a tuple, checked: one or more of :data:`FEATURES`, each once; ``b`` / ``bm`` need a
    ``skeleton`` of :data:`BONE_PAIRS` (when one is given).

    Raises:
        ValueError: naming the feature or the skeleton at fault.
    """
    if isinstance(feats, str):
        raise ValueError(f"feats must be a list of features such as [j, b], got the string {feats!r}")
    feats = tuple(feats)
    if not feats:
        raise ValueError(f"feats must name at least one of {list(FEATURES)}")
    unknown = [f for f in feats if f not in FEATURES]
    if unknown:
        raise ValueError(f"unknown skeleton feature {unknown[0]!r}; known: {list(FEATURES)}")
    if len(set(feats)) != len(feats):
        raise ValueError(f"feats {list(feats)} names a feature twice")
    if skeleton is not None and {"b", "bm"} & set(feats) and skeleton not in BONE_PAIRS:
        raise ValueError(f"no PYSKL bone pairs for skeleton {skeleton!r} (bones: {sorted(BONE_PAIRS)})")
    return feats


def joint_to_bone(keypoint: np.ndarray, skeleton: str) -> np.ndarray:
    """[PYSKL] ``JointToBone``: every joint minus the joint its pair in :data:`BONE_PAIRS` names.

    Args:
        keypoint: (M, T, V, C) joints, C = 3 (x y z; or x y score for :data:`SCORE_LAYOUTS`) or 2.
        skeleton: the joint layout (a key of :data:`BONE_PAIRS`).

    Returns:
        (M, T, V, C) float64 bones; with a score channel, each bone's score is the mean of its two joints'.
    """
    keypoint = np.asarray(keypoint, dtype=np.float64)
    check_features(("b",), skeleton)
    pairs = np.asarray(BONE_PAIRS[skeleton])
    if keypoint.ndim != 4 or keypoint.shape[-1] not in (2, 3) or keypoint.shape[2] != len(pairs):
        raise ValueError(f"joint_to_bone expects (M, T, {len(pairs)}, C=2|3) {skeleton} joints, "
                         f"got shape {keypoint.shape}")  # fmt: skip
    child, parent = pairs[:, 0], pairs[:, 1]
    bone = np.zeros_like(keypoint)
    bone[..., child, :] = keypoint[..., child, :] - keypoint[..., parent, :]
    if keypoint.shape[-1] == 3 and skeleton in SCORE_LAYOUTS:
        bone[..., child, 2] = (keypoint[..., child, 2] + keypoint[..., parent, 2]) / 2
    return bone


def to_motion(data: np.ndarray, score: bool = False) -> np.ndarray:
    """[PYSKL] ``ToMotion``: the next frame minus this one along T; the last frame's motion is zero.

    Args:
        data: (M, T, V, C) joints or bones.
        score: channel 2 is a confidence score: the mean of the two frames' scores instead of a difference
            (zero at the last frame, as every channel there).

    Returns:
        (M, T, V, C) float64.
    """
    data = np.asarray(data, dtype=np.float64)
    if data.ndim != 4:
        raise ValueError(f"to_motion expects (M, T, V, C) data, got shape {data.shape}")
    motion = np.zeros_like(data)
    motion[:, :-1] = np.diff(data, axis=1)
    if score:
        motion[:, :-1, :, 2] = (data[:, :-1, :, 2] + data[:, 1:, :, 2]) / 2
    return motion


def skeleton_features(keypoint: np.ndarray, feats: Sequence[str], skeleton: str | None = None) -> np.ndarray:
    """[PYSKL] ``GenSkeFeat(feats)``: the features named, concatenated on the channel axis in that order.

    Args:
        keypoint: (M, T, V, C) joints of the whole (normalised) sequence; C = 3 with a score channel for
            the 2-D layouts of :data:`SCORE_LAYOUTS` (x, y, score), else coordinates.
        feats: one or more of :data:`FEATURES`: ``j`` joints, ``b`` bones (:func:`joint_to_bone`), ``jm``
            joint motion, ``bm`` bone motion (:func:`to_motion`).
        skeleton: the joint layout: a key of :data:`BONE_PAIRS` for ``b`` / ``bm``; it also says whether
            channel 2 is a score. None: joints and joint motion of coordinates only.

    Returns:
        (M, T, V, len(feats) * C) float32.
    """
    feats = check_features(feats)
    keypoint = np.asarray(keypoint)
    if keypoint.ndim != 4:
        raise ValueError(f"skeleton_features expects (M, T, V, C) joints, got shape {keypoint.shape}")
    if {"b", "bm"} & set(feats) and skeleton not in BONE_PAIRS:
        raise ValueError(f"bone features need a skeleton of {sorted(BONE_PAIRS)}, got {skeleton!r}")
    score = keypoint.shape[-1] == 3 and skeleton in SCORE_LAYOUTS
    out = {"j": np.asarray(keypoint, dtype=np.float64)}
    if {"b", "bm"} & set(feats):
        out["b"] = joint_to_bone(out["j"], skeleton)
    if "jm" in feats:
        out["jm"] = to_motion(out["j"], score)
    if "bm" in feats:
        out["bm"] = to_motion(out["b"], score)
    return np.concatenate([out[f] for f in feats], axis=-1).astype(np.float32)


def _integers(rng: np.random.Generator | np.random.RandomState, high):
    return rng.integers(high) if isinstance(rng, np.random.Generator) else rng.randint(high)


def uniform_sample_indices(
    total_frames: int,
    clip_len: int = 100,
    num_clips: int = 1,
    test_mode: bool = False,
    rng: np.random.Generator | None = None,
    seed: int = 255,
    p_interval: tuple[float, float] = (1.0, 1.0),
) -> np.ndarray:
    """PYSKL ``UniformSampleFrames`` frame indices.

    Each clip splits the (optionally randomly cropped, ``p_interval``) sequence into ``clip_len`` equal
    segments and takes one random frame per segment; a sequence shorter than ``clip_len`` is looped from a
    start frame, and one shorter than ``2 * clip_len`` takes every frame once plus random repeats.

    Args:
        total_frames: T > 0.
        clip_len: frames per clip.
        num_clips: clips drawn (PYSKL tests with 10).
        test_mode: draw from a fresh ``RandomState(seed)`` (PYSKL reseeds the global generator with 255),
            so the result depends only on the arguments; ``rng`` is ignored.
        rng: generator for training; a fresh unseeded one when None.
        seed: the test-mode seed.
        p_interval: fraction range of the sequence kept before sampling (CTR-GCN crop); (1, 1) keeps all.

    Returns:
        (num_clips * clip_len,) int64 indices in [0, total_frames).
    """
    if total_frames < 1:
        raise ValueError(f"uniform_sample_indices needs total_frames >= 1, got {total_frames}")
    if test_mode:
        rng = np.random.RandomState(seed)
    elif rng is None:
        rng = np.random.default_rng()
    clips = []
    for i in range(num_clips):
        ratio = rng.random() * (p_interval[1] - p_interval[0]) + p_interval[0]
        num_frames = int(ratio * total_frames)
        off = _integers(rng, total_frames - num_frames + 1)
        if num_frames < clip_len:
            if test_mode:
                start = i if num_frames < num_clips else i * num_frames // num_clips
            else:
                start = _integers(rng, num_frames)
            inds = np.arange(start, start + clip_len)
        elif num_frames < 2 * clip_len:
            chosen = rng.choice(clip_len + 1, num_frames - clip_len, replace=False)
            offset = np.zeros(clip_len + 1, dtype=np.int64)
            offset[chosen] = 1
            inds = np.arange(clip_len) + np.cumsum(offset)[:-1]
        else:
            bids = np.array([k * num_frames // clip_len for k in range(clip_len + 1)])
            inds = bids[:clip_len] + _integers(rng, np.diff(bids))
        clips.append(inds + off)
    return np.mod(np.concatenate(clips), total_frames).astype(np.int64)


def random_scale(
    keypoint: np.ndarray, rng: np.random.Generator | np.random.RandomState, scale: float
) -> np.ndarray:
    """[PYSKL] ``RandomScale(scale)``: every coordinate axis scaled by its own ``1 + U(-1, 1) * scale``.

    Draws ``uniform(-1, 1, size=C)`` on every call, also for ``scale = 0`` (as PYSKL, whose transform draws
    whenever it is in the pipeline); the factors do not depend on the joints.

    Args:
        keypoint: (M, T, V, C) joints.
        rng: the random generator (a ``RandomState`` seeded like PYSKL's global ``np.random``: its draws).
        scale: the range; each axis is scaled by a factor in [1 - scale, 1 + scale].

    Returns:
        (M, T, V, C) float32; zero joints stay zero.
    """
    keypoint = np.asarray(keypoint, dtype=np.float32)
    factors = 1.0 + rng.uniform(-1.0, 1.0, size=keypoint.shape[-1]) * scale
    return (keypoint * factors).astype(np.float32)


def random_rot(
    keypoint: np.ndarray, rng: np.random.Generator | np.random.RandomState, theta: float = 0.3
) -> np.ndarray:
    """[PYSKL] ``RandomRot(theta)``: one random rotation of the whole sample.

    PYSKL pyskl/datasets/pipelines/pose_related.py: nothing is drawn when every joint is (close to) zero;
    else for C = 3 three angles ``t = uniform(-theta, theta, size=3)`` and ``R = Rz Ry Rx`` with PYSKL's
    matrices, which turn by ``-t`` about each axis (``Rotation.from_euler("xyz", -t)``); for C = 2 one angle
    ``t = uniform(-theta)``, i.e. uniform on ``[-theta, 1)`` rad (numpy's default upper bound 1.0; PYSKL's
    2-D range, kept for parity), and ``R = [[cos t, -sin t], [sin t, cos t]]``. Every joint becomes ``R x``.

    Args:
        keypoint: (M, T, V, C) joints, C = 3 (or 2 for image-plane skeletons).
        rng: the random generator.
        theta: the angle range in radians.

    Returns:
        (M, T, V, C) float32; all-zero (absent) joints stay zero.
    """
    keypoint = np.asarray(keypoint, dtype=np.float32)
    c = keypoint.shape[-1]
    if c not in (2, 3):
        raise ValueError(f"random_rot expects C = 2 or 3 coordinates, got shape {keypoint.shape}")
    if np.all(np.isclose(keypoint, 0)):
        return keypoint.copy()
    if c == 3:
        matrix = Rotation.from_euler("xyz", -rng.uniform(-theta, theta, size=3)).as_matrix()
    else:
        t = rng.uniform(-theta)
        matrix = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    return (keypoint @ matrix.T).astype(np.float32)


def random_rotate_scale(
    keypoint: np.ndarray,
    rng: np.random.Generator | np.random.RandomState,
    max_angle: float | None = 0.3,
    scale_range: float | None = None,
) -> np.ndarray:
    """[PYSKL] ``RandomScale(scale_range)`` then ``RandomRot(max_angle)``, each only when switched on.

    A transform that is off (``None`` or 0) is left out of the pipeline and draws nothing, so with
    ``np.random.RandomState(seed)`` as ``rng`` the result equals PYSKL's after ``np.random.seed(seed)`` for
    the pipeline holding just the transforms that are on: scale only, rotation only, both, or neither.
    (PYSKL's ``RandomScale(0.0)`` / ``RandomRot(0)`` in a pipeline would still draw: call
    :func:`random_scale` / :func:`random_rot` for those.)

    Args:
        keypoint: (M, T, V, C) joints, C = 3 (or 2 for image-plane skeletons).
        rng: the random generator.
        max_angle: ``RandomRot``'s ``theta`` (radians); ``None`` or 0: no rotation.
        scale_range: ``RandomScale``'s ``scale``; ``None`` or 0: no scaling.

    Returns:
        (M, T, V, C) float32; all-zero (absent) joints stay zero.
    """
    keypoint = np.asarray(keypoint, dtype=np.float32)
    if keypoint.shape[-1] not in (2, 3):
        raise ValueError(f"random_rotate_scale expects C = 2 or 3 coordinates, got shape {keypoint.shape}")
    if scale_range:
        keypoint = random_scale(keypoint, rng, scale_range)
    if max_angle:
        keypoint = random_rot(keypoint, rng, max_angle)
    return keypoint


class SkeletonPipeline:
    """One annotation -> (num_clips, M, clip_len, V, C) float32 network input (PYSKL GCN pipeline).

    3D (C = 3, x y z): ``pre_normalize_3d`` -> [train: ``random_rotate_scale``] -> ``skeleton_features``
    -> sampling -> bodies.
    2D (``keypoint_score`` present): ``pre_normalize_2d`` with the annotation's ``img_shape`` -> score
    appended as a third channel (x, y, score) as PYSKL ``GenSkeFeat`` does -> [train: ``random_rotate_scale``
    of x, y: PYSKL's transforms on (M, T, V, 2) keypoints, C = 2] -> ``skeleton_features`` -> sampling ->
    bodies. (PYSKL's own ``PreNormalize2D`` merges the score into a third channel, so a PYSKL 2-D config with
    ``RandomRot``, of which it ships none, would turn (x, y, score) as if 3-D.) With ``feats`` other than
    ``("j",)`` the output has ``len(feats) * C`` channels per joint.

    The order is PYSKL's: its configs that augment (``configs/strong_aug/*/j.py``, ``configs/dgstgcn/*/j.py``)
    run ``RandomScale`` / ``RandomRot`` on the whole normalised sequence before ``UniformSample``, so the
    draws come scale, rotation, then sampling, and with ``np.random.RandomState(seed)`` as ``rng`` the output
    equals PYSKL's after ``np.random.seed(seed)``. ``augment_before_sampling=False`` samples first and
    augments the sampled clips (the order of the 2s-AGCN / CTR-GCN feeders: sampling draws first); the
    features are then computed on the whole sequence before sampling and the one drawn scale and rotation
    turn every feature alike (bones and motions are differences of joints, so this equals augmenting the
    joints first).

    Args:
        clip_len: frames per clip (PYSKL GCN configs: 100).
        num_clips: clips per sample (PYSKL: 1 for training / validation, 10 for testing).
        test_mode: deterministic sampling (seeded as PYSKL) and no augmentation.
        num_person: bodies in the output (zero-padded).
        max_angle: training ``RandomRot`` angle range in radians (0 = no ``RandomRot``, nothing drawn: PYSKL's
            ST-GCN++ configs; strong_aug: 0.3).
        scale_range: training ``RandomScale`` range (0 = no ``RandomScale``, nothing drawn; strong_aug: 0.1).
        img_shape: (height, width) for 2D data without ``img_shape`` in the annotation.
        seed: the test-mode sampling seed.
        augment_before_sampling: augment the whole sequence, then sample (PYSKL); False: sample, then augment.
        feats: the [PYSKL] ``GenSkeFeat`` features (:data:`FEATURES`): ``("j",)`` joints (the default),
            ``("b",)``, ``("jm",)``, ``("bm",)`` or several, concatenated in that order.
        skeleton: the joint layout (:data:`BONE_PAIRS`): needed for ``b`` / ``bm``, and for a 2-D layout's
            score channel in the motion features.
    """

    def __init__(
        self,
        clip_len: int = 100,
        num_clips: int = 1,
        test_mode: bool = False,
        num_person: int = 2,
        max_angle: float = 0.0,
        scale_range: float = 0.0,
        img_shape: tuple[float, float] = (1080, 1920),
        seed: int = 255,
        augment_before_sampling: bool = True,
        feats: Sequence[str] = ("j",),
        skeleton: str | None = None,
    ) -> None:
        self.feats = check_features(feats, skeleton)
        if {"b", "bm"} & set(self.feats) and skeleton is None:
            raise ValueError(f"feats {list(self.feats)} need the skeleton layout for the bones")
        self.skeleton = skeleton
        self.clip_len = clip_len
        self.num_clips = num_clips
        self.test_mode = test_mode
        self.num_person = num_person
        self.max_angle = max_angle
        self.scale_range = scale_range
        self.img_shape = img_shape
        self.seed = seed
        self.augment_before_sampling = augment_before_sampling

    def _augment(
        self, keypoint: np.ndarray, xyz: int, width: int, rng: np.random.Generator | np.random.RandomState
    ) -> np.ndarray:
        """``random_rotate_scale`` of the first ``xyz`` channels of every ``width``-channel feature of (M, T,
        V, F * width) ``keypoint``, one draw for all (the features side by side as F * V joints)."""
        m, t, v, c = keypoint.shape
        chunks = np.array(keypoint, dtype=np.float32).reshape(m, t, v * (c // width), width)
        chunks[..., :xyz] = random_rotate_scale(chunks[..., :xyz], rng, self.max_angle, self.scale_range)
        return chunks.reshape(m, t, v, c)

    def __call__(
        self, annotation: Mapping, rng: np.random.Generator | np.random.RandomState | None = None
    ) -> np.ndarray:
        """Apply the pipeline to one annotation dict (``keypoint`` and optionally ``keypoint_score``).

        Args:
            annotation: a PYSKL annotation (see :func:`.pyskl.load_annotations`).
            rng: training randomness (a fresh generator when None; unused in test mode).

        Returns:
            (num_clips, num_person, clip_len, V, C) float32.
        """
        rng = np.random.default_rng() if rng is None else rng
        keypoint = np.asarray(annotation["keypoint"], dtype=np.float32)
        if "keypoint_score" in annotation:
            img_shape = annotation.get("img_shape", self.img_shape)
            xy = pre_normalize_2d(keypoint, annotation["keypoint_score"], img_shape)
            score = np.asarray(annotation["keypoint_score"], np.float32)
            keypoint = np.concatenate([xy, score[..., None]], -1)
            xyz = 2
        else:
            keypoint = pre_normalize_3d(keypoint)
            xyz = 3
        width = keypoint.shape[-1]  # channels of one feature
        if keypoint.shape[1] == 0:
            raise ValueError(f"{annotation.get('frame_dir', '<sample>')}: no frame with a body to sample")
        augment = not self.test_mode and bool(self.max_angle or self.scale_range)
        if augment and self.augment_before_sampling:
            keypoint = self._augment(keypoint, xyz, width, rng)
        if self.feats != ("j",):  # PYSKL GenSkeFeat: after PreNormalize / RandomScale / RandomRot
            keypoint = skeleton_features(keypoint, self.feats, self.skeleton)
        m, t, v, c = keypoint.shape
        inds = uniform_sample_indices(t, self.clip_len, self.num_clips, self.test_mode, rng, self.seed)
        clips = keypoint[:, inds]  # (M, num_clips * clip_len, V, C)
        if augment and not self.augment_before_sampling:
            clips = self._augment(clips, xyz, width, rng)
        clips = keep_bodies(clips, self.num_person)
        clips = clips.reshape(self.num_person, self.num_clips, self.clip_len, v, c).transpose(1, 0, 2, 3, 4)
        return np.ascontiguousarray(clips, dtype=np.float32)
