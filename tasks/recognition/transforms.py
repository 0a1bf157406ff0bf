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
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "SkeletonPipeline",
    "keep_bodies",
    "pre_normalize_2d",
    "pre_normalize_3d",
    "random_rot",
    "random_rotate_scale",
    "random_scale",
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

    3D (C = 3, x y z): ``pre_normalize_3d`` -> [train: ``random_rotate_scale``] -> sampling -> bodies.
    2D (``keypoint_score`` present): ``pre_normalize_2d`` with the annotation's ``img_shape`` -> score
    appended as a third channel (x, y, score) as PYSKL ``GenSkeFeat`` does -> [train: ``random_rotate_scale``
    of x, y: PYSKL's transforms on (M, T, V, 2) keypoints, C = 2] -> sampling -> bodies. (PYSKL's own
    ``PreNormalize2D`` merges the score into a third channel, so a PYSKL 2-D config with ``RandomRot``, of
    which it ships none, would turn (x, y, score) as if 3-D.)

    The order is PYSKL's: its configs that augment (``configs/strong_aug/*/j.py``, ``configs/dgstgcn/*/j.py``)
    run ``RandomScale`` / ``RandomRot`` on the whole normalised sequence before ``UniformSample``, so the
    draws come scale, rotation, then sampling, and with ``np.random.RandomState(seed)`` as ``rng`` the output
    equals PYSKL's after ``np.random.seed(seed)``. ``augment_before_sampling=False`` samples first and
    augments the sampled clips (the order of the 2s-AGCN / CTR-GCN feeders: sampling draws first).

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
    ) -> None:
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
        self, keypoint: np.ndarray, xyz: int, rng: np.random.Generator | np.random.RandomState
    ) -> None:
        """In place: ``random_rotate_scale`` of the first ``xyz`` channels of (M, T, V, C) ``keypoint``."""
        keypoint[..., :xyz] = random_rotate_scale(keypoint[..., :xyz], rng, self.max_angle, self.scale_range)

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
        m, t, v, c = keypoint.shape
        if t == 0:
            raise ValueError(f"{annotation.get('frame_dir', '<sample>')}: no frame with a body to sample")
        augment = not self.test_mode and bool(self.max_angle or self.scale_range)
        if augment and self.augment_before_sampling:
            self._augment(keypoint, xyz, rng)
        inds = uniform_sample_indices(t, self.clip_len, self.num_clips, self.test_mode, rng, self.seed)
        clips = keypoint[:, inds]  # (M, num_clips * clip_len, V, C)
        if augment and not self.augment_before_sampling:
            self._augment(clips, xyz, rng)
        clips = keep_bodies(clips, self.num_person)
        clips = clips.reshape(self.num_person, self.num_clips, self.clip_len, v, c).transpose(1, 0, 2, 3, 4)
        return np.ascontiguousarray(clips, dtype=np.float32)
