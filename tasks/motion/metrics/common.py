"""Input handling shared by the dance metrics: batches or lists of variable-length joint sequences."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

__all__ = ["as_sequences", "beat_indices"]

Positions = torch.Tensor | np.ndarray | Sequence[torch.Tensor | np.ndarray]


def as_sequences(positions: Positions, min_frames: int = 2, joints: int | None = None) -> list[torch.Tensor]:
    """Split joint positions into a list of ``(T_i, J, 3)`` float64 tensors.

    Args:
        positions: a ``(B, T, J, 3)`` batch, one ``(T, J, 3)`` sequence, or a list of ``(T_i, J, 3)``
            sequences of different lengths (tensors or numpy arrays).
        min_frames: the fewest frames a sequence may have.
        joints: the required joint count (``None`` accepts any).
    """
    if isinstance(positions, (torch.Tensor, np.ndarray)):
        tensor = torch.as_tensor(positions)
        if tensor.ndim == 3:
            tensor = tensor[None]
        if tensor.ndim != 4:
            raise ValueError(f"positions must be (B, T, J, 3) or (T, J, 3), got {tuple(tensor.shape)}")
        items = list(tensor.unbind(0))
    else:
        items = [torch.as_tensor(p) for p in positions]
    out = []
    for i, seq in enumerate(items):
        if seq.ndim != 3 or seq.shape[-1] != 3:
            raise ValueError(f"sequence {i}: expected (T, J, 3) joint positions, got {tuple(seq.shape)}")
        if joints is not None and seq.shape[1] != joints:
            raise ValueError(f"sequence {i}: expected {joints} joints, got {seq.shape[1]}")
        if seq.shape[0] < min_frames:
            raise ValueError(f"sequence {i}: needs at least {min_frames} frames, got {seq.shape[0]}")
        if not torch.isfinite(seq).all():
            raise ValueError(f"sequence {i}: joint positions contain NaN or inf")
        out.append(seq.detach().to(device="cpu", dtype=torch.float64))
    return out


def beat_indices(beats: torch.Tensor | np.ndarray | Sequence[int]) -> np.ndarray:
    """Beat frame indices from a one-hot ``(T,)`` vector or a list of indices.

    Boolean arrays and floating arrays holding only 0 and 1 (like column 34 of the music features) are
    read as one-hot; integer arrays and lists of ints are read as sorted frame indices.
    """
    array = np.asarray(beats.cpu() if isinstance(beats, torch.Tensor) else beats)
    if array.ndim != 1:
        raise ValueError(f"beats must be 1-D (one-hot or indices), got shape {array.shape}")
    if array.dtype == bool or (np.issubdtype(array.dtype, np.floating) and np.isin(array, (0.0, 1.0)).all()):
        return np.flatnonzero(array)
    indices = np.sort(array.astype(np.int64))
    if indices.size > 2 and np.unique(indices).size < indices.size and np.isin(indices, (0, 1)).all():
        raise ValueError("integer beats look like a one-hot vector: pass one-hot beats as bool or float")
    return indices
