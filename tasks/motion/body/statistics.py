"""Per-channel statistics of training data: the mean and standard deviation a model standardises with.

Used for the diffusion preconditioning of EMM and the text-to-motion denoiser (motion tokens, HumanML3D
features) and for the music standardisation of the EMM's music encoder and the streaming dancer.
"""

from __future__ import annotations

import torch


def channel_statistics(
    data: torch.Tensor, channel_dims: int = 1, min_std: float = 0.0, name: str = "data"
) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and population standard deviation per channel, over every other axis, in float64.

    Args:
        data: (..., *C) training values; the last ``channel_dims`` axes are the channels C.
        channel_dims: how many trailing axes form a channel (2 for motion tokens (N, T, 24, 10)).
        min_std: the floor of the standard deviation (a constant channel would divide by 0).
        name: what ``data`` is, for the error message.

    Returns:
        (mean, std), each of shape C, float32.

    Raises:
        ValueError: ``data`` contains NaN or inf (statistics of it would spoil every later output).
    """
    flat = data.reshape(-1, *data.shape[data.dim() - channel_dims :]).double()
    if not torch.isfinite(flat).all():
        raise ValueError(f"{name} statistics: the values contain NaN or inf")
    return flat.mean(0).float(), flat.std(0, correction=0).clamp(min=min_std).float()


__all__ = ["channel_statistics"]
