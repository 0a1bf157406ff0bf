"""Tiny recognition configurations and skeleton sequences shared by the recognition tests."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from tests.helpers.motions import STANDING

TINY = SkeletonMambaConfig(
    skeleton="ntu25",
    in_channels=3,
    dim=16,
    depth=1,
    heads=2,
    mlp_dim=32,
    group_paths=[[1, 2, 0, 3, 4]],
    mixer=MixerConfig(d_state=16, headdim=8, chunk_size=16),
)


def moved_person(frames: int, seed: int) -> np.ndarray:
    """(frames, 25, 3): the standing template under a random rotation and translation, slightly moving."""
    rng = np.random.default_rng(seed)
    rot = Rotation.random(random_state=seed).as_matrix()
    base = STANDING @ rot.T + rng.uniform(-2, 2, 3)
    return base[None] + 0.01 * np.arange(frames)[:, None, None]


def pyskl_test_indices(num_frames: int, clip_len: int, num_clips: int, seed: int = 255) -> np.ndarray:
    """PYSKL ``UniformSampleFrames._get_test_clips`` (p_interval 1), transcribed with numpy's global RNG."""
    # ruff: NPY002 is the point here: PYSKL reseeds and draws from the legacy global generator
    np.random.seed(seed)  # noqa: NPY002
    all_inds = []
    for i in range(num_clips):
        ratio = np.random.rand() * 0 + 1  # noqa: NPY002
        n = int(ratio * num_frames)
        off = np.random.randint(num_frames - n + 1)  # noqa: NPY002
        if n < clip_len:
            start_ind = i if n < num_clips else i * n // num_clips
            inds = np.arange(start_ind, start_ind + clip_len)
        elif clip_len <= n < clip_len * 2:
            basic = np.arange(clip_len)
            inds = np.random.choice(clip_len + 1, n - clip_len, replace=False)  # noqa: NPY002
            offset = np.zeros(clip_len + 1, dtype=np.int64)
            offset[inds] = 1
            inds = basic + np.cumsum(offset)[:-1]
        else:
            bids = np.array([i * n // clip_len for i in range(clip_len + 1)])
            inds = bids[:clip_len] + np.random.randint(np.diff(bids))  # noqa: NPY002
        all_inds.append(inds + off)
    return np.mod(np.concatenate(all_inds), num_frames)
