"""A bounded working set on CPU: run an index-independent function on slices of its input.

The per-frame scans (Group Scan, Joint Scan), the per-token sublayers and the per-joint Temporal
Scan treat frames (or joint sequences) independently, so ``f(x)`` equals ``cat([f(s) for s in
x.split(n, dim)], dim)``. On a CPU, one call over a long sequence creates intermediates of hundreds
of MB: each is a fresh ``mmap`` that the kernel zero-fills page by page (glibc serves every block
above its 32 MB threshold that way), so unsliced the backbone grows faster than linearly in T and
spends most of a short sequence's time in page faults. Slices of a few MB stay in cache and are
served again and again from the heap. On CUDA the whole input goes through in one call, and so it
does under ``torch.compile``: the slices would be traced one by one (a graph many times the size of
one call's, compiling for many minutes), and the compiled code fuses most intermediates away.
"""

from __future__ import annotations

from collections.abc import Callable

import torch


def slice_length(x: torch.Tensor, dim: int, elements_per_index: int, budget: int | None) -> int:
    """How many indices along ``dim`` one slice holds.

    Args:
        x: the input that would be sliced.
        dim: the independent dimension.
        elements_per_index: elements of the widest intermediate per index along ``dim``.
        budget: at most this many elements of that intermediate per slice (``None``: no slicing).

    Returns:
        ``x.shape[dim]`` (one call) on CUDA, under ``torch.compile``, without a budget or when it all
        fits; else at least 1.
    """
    length = x.shape[dim]
    if budget is None or x.device.type != "cpu" or torch.compiler.is_compiling():
        return length
    return max(1, min(length, budget // max(1, elements_per_index)))


def map_slices(
    fn: Callable[..., torch.Tensor], dim: int, length: int, *tensors: torch.Tensor
) -> torch.Tensor:
    """``fn(*tensors)`` computed on slices of ``length`` along ``dim`` of every tensor and concatenated.

    All ``tensors`` share the size of ``dim``; ``fn`` must treat the indices along ``dim``
    independently and keep that dimension in its output.
    """
    if length >= tensors[0].shape[dim]:
        return fn(*tensors)
    pieces = zip(*(t.split(length, dim) for t in tensors))
    return torch.cat([fn(*piece) for piece in pieces], dim)
