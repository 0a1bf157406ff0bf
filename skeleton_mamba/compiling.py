"""Compiled inference: ``torch.compile`` (inductor) with the weights frozen into the graph.

On a CPU most of a Skeleton Mamba step that is not a matrix product is element-wise work on small
tensors (the Group Scan's 40-token path sequences: causal convolution taps, SiLU, gated RMSNorm, decay
masks, layout copies), each a separate PyTorch operation that reads and writes its whole input.
Inductor fuses chains of them into single loops, and with ``freezing`` it treats the parameters as
constants: it folds what depends only on them (e.g. ``-exp(A_log)``) and prepacks the weights of the
matrix products for oneDNN (``benchmarks/README.md``, compiled rows, for the gains measured).

Frozen means frozen: the compiled function keeps the parameter values of its first call. Compile a
model whose weights no longer change (sampling from a checkpoint), under ``torch.no_grad`` or
``torch.inference_mode`` (freezing applies to inference graphs only). Shapes are compiled statically:
a new input shape compiles again.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

__all__ = ["compile_for_inference"]


def compile_for_inference(fn: Callable) -> Callable:
    """``fn`` (a module or function) compiled by inductor with weight freezing and static shapes.

    The first call compiles (about a minute for the seed-size EMM denoiser on 2 CPU cores); later calls
    with the same input shapes run the compiled code. Outputs equal ``fn``'s to float32 rounding.
    """
    return torch.compile(fn, dynamic=False, options={"freezing": True})
