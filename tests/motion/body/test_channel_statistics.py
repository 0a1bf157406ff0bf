"""Per-channel training statistics (``tasks/motion/body/statistics.py``) against numpy."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.motion.body.statistics import channel_statistics


def test_statistics_per_channel_over_every_other_axis_as_numpy():
    rng = np.random.default_rng(0)
    data = rng.normal(3.0, 2.0, size=(4, 7, 5, 3)) * np.arange(1, 4)  # channels (5, 3) on different scales
    data[..., 0, 0] = 1.5  # a constant channel
    mean, std = channel_statistics(torch.from_numpy(data), channel_dims=2, min_std=1e-2)
    flat = data.reshape(-1, 5, 3)
    assert mean.shape == std.shape == (5, 3) and mean.dtype == std.dtype == torch.float32
    np.testing.assert_allclose(mean.numpy(), flat.mean(0), rtol=1e-6)
    expected = np.maximum(flat.std(0, ddof=0), 1e-2)  # population std, floored
    np.testing.assert_allclose(std.numpy(), expected, rtol=1e-6)
    assert std[0, 0] == pytest.approx(1e-2)
    one_axis = channel_statistics(torch.from_numpy(data).reshape(-1, 15).float())
    np.testing.assert_allclose(one_axis[0].numpy(), flat.reshape(-1, 15).mean(0), rtol=1e-5)


def test_non_finite_training_data_is_refused_by_name():
    data = torch.zeros(10, 3)
    data[4, 1] = float("inf")
    with pytest.raises(ValueError, match="music statistics.*NaN or inf"):
        channel_statistics(data, name="music")
