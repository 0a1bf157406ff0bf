"""The largest value each size of a network may take, by name: what a pretrained folder's ``config.json``, a
checkpoint's hyper-parameters or a command's option (``sm export-onnx --in-channels``) may state before
anything is built (:func:`skeleton_mamba.pretrained.checks.check_sizes`).

Plain Python (no torch): the commands' parsers range-check their options with these bounds before torch is
imported.
"""

from __future__ import annotations

__all__ = ["SIZE_BOUNDS", "size_bound"]

# The largest value each size may take ([EgoMusic] supp. Table 2 sizes in the comments), by field or argument
# name wherever it appears (config dataclasses, __init__ arguments, a module's hyper-parameters). A list
# (ResNet stage widths) is bounded entry by entry.
SIZE_BOUNDS: dict[str, int] = {
    "dim": 4096,  # 128
    "depth": 256,  # 8
    "mlp_dim": 65_536,  # 1024
    "heads": 256,  # 4
    "d_state": 1024,  # 64
    "headdim": 1024,  # 64
    "expand": 16,  # 2
    "ngroups": 256,
    "d_conv": 64,  # 4
    "d_ssm": 65_536,
    "chunk_size": 8192,
    "in_channels": 65_536,
    "out_channels": 65_536,
    "hidden": 65_536,
    "transformer_ff": 65_536,
    "embedding_size": 65_536,
    "hidden_sizes": 65_536,
    "channels": 65_536,
    "depths": 256,
    "layers": 256,
    "input_size": 4096,
    "image_size": 4096,
    "num_classes": 100_000,
    "diffusion_steps": 100_000,
    "sampling_steps": 100_000,
    "num_periods": 1024,
    "conv_kernel": 1024,
}
# Names not listed above, by their ending.
_SUFFIX_BOUNDS: tuple[tuple[str, int], ...] = (("_layers", 256), ("_dim", 65_536), ("_frames", 1_000_000))


def size_bound(name: str) -> int | None:
    """The largest value a size called ``name`` may take (:data:`SIZE_BOUNDS`), None when it is no size."""
    if name in SIZE_BOUNDS:
        return SIZE_BOUNDS[name]
    return next((bound for suffix, bound in _SUFFIX_BOUNDS if name.endswith(suffix)), None)
