"""Optional GPU backend: mamba-ssm's fused Triton chunk scan ([Mamba-2], ``mamba_chunk_scan_combined``).

``mamba_ssm`` imports Triton at import time and its kernels run on CUDA only, so it is imported
lazily, inside :func:`ssd_kernel`, and :func:`kernel_available` checks both conditions first.
The Triton path needs none of mamba-ssm's compiled CUDA extensions, so it also works from an install
without them (``MAMBA_SKIP_CUDA_BUILD=TRUE``): :func:`import_triton_ssd` then loads the Triton modules
without running the package ``__init__``, which imports the Mamba-1 extension eagerly.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import sys
import types

import torch

from skeleton_mamba.ssd.discretize import NO_DT_LIMIT

KERNEL_MODULE = "mamba_ssm.ops.triton.ssd_combined"
KERNEL_TF32_ERROR = 1e-2
"""Bound on the kernel's fp32 error, relative to the largest value: its Triton matrix products take fp32
inputs in TF32 (``tl.dot``'s default on Ampere and later GPUs). On an H200 (mamba-ssm 2.3.2.post1, Triton
3.6) the output was off from float64 by 2.0e-3 of its largest value and the gradients by up to 3.1e-3, where
the pure-PyTorch SSD in fp32 is within 3e-7."""


def is_cuda(t: torch.Tensor) -> bool:
    """Whether ``t`` lives on a CUDA device (a seam the tests replace to fake a GPU)."""
    return bool(t.is_cuda)


def mamba_ssm_installed() -> bool:
    """Whether the ``mamba_ssm`` package can be imported (without importing it), or already is."""
    try:
        return importlib.util.find_spec("mamba_ssm") is not None
    except (ImportError, ValueError):
        return False


def import_triton_ssd() -> types.ModuleType:
    """``mamba_ssm.ops.triton.ssd_combined``, also from an install without the compiled extensions.

    mamba-ssm's ``__init__`` imports ``selective_scan_cuda`` (Mamba-1's CUDA extension) unconditionally;
    when that extension was not built, the package is registered as a bare namespace over its
    installed folder so that its pure-Triton submodules import on their own.
    """
    try:
        return importlib.import_module(KERNEL_MODULE)
    except ImportError as err:
        if "selective_scan_cuda" not in str(err):
            raise
    spec = importlib.util.find_spec("mamba_ssm")
    package = types.ModuleType("mamba_ssm")
    package.__path__ = list(spec.submodule_search_locations)
    # A spec of its own (a namespace: no loader), so that find_spec and mamba_ssm_installed still see the
    # package once it is registered; without it every later ``ssd(impl="auto")`` fell back to PyTorch.
    package.__spec__ = importlib.machinery.ModuleSpec("mamba_ssm", None, is_package=True)
    package.__spec__.submodule_search_locations = package.__path__
    for name in [m for m in sys.modules if m == "mamba_ssm" or m.startswith("mamba_ssm.")]:
        del sys.modules[name]  # partial modules left by the failed import
    sys.modules["mamba_ssm"] = package
    return importlib.import_module(KERNEL_MODULE)


def kernel_available(x: torch.Tensor) -> bool:
    """True when the Triton kernel can run on ``x``: mamba-ssm installed and x on CUDA."""
    return is_cuda(x) and mamba_ssm_installed()


def ssd_kernel(
    x: torch.Tensor,
    dt: torch.Tensor,
    A: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    *,
    D: torch.Tensor | None = None,
    dt_bias: torch.Tensor | None = None,
    dt_softplus: bool = True,
    dt_limit: tuple[float, float] = NO_DT_LIMIT,
    initial_state: torch.Tensor | None = None,
    return_final_state: bool = False,
    chunk_size: int = 64,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """SSD through ``mamba_chunk_scan_combined``; arguments and results as :func:`ssd_recurrence`.

    The kernel takes the same raw dt, continuous A, and grouped B/C layout, so arguments map
    one to one (``initial_state`` -> ``initial_states``, ``return_final_state`` ->
    ``return_final_states``); the state is returned in fp32.

    Raises:
        RuntimeError: mamba-ssm is not installed or x is not on a CUDA device.
    """
    if not is_cuda(x):
        raise RuntimeError(
            "ssd(impl='kernel'): the mamba-ssm Triton kernel needs CUDA tensors, x is on "
            f"{x.device}; use impl='chunked' or 'auto' on CPU"
        )
    try:
        module = import_triton_ssd()
    except ImportError as err:
        raise RuntimeError(
            "ssd(impl='kernel') needs mamba-ssm (pip install mamba-ssm --no-build-isolation): "
            f"importing {KERNEL_MODULE} failed: {err}"
        ) from err
    out = module.mamba_chunk_scan_combined(
        x,
        dt,
        A,
        B,
        C,
        chunk_size,
        D=D,
        z=None,
        dt_bias=dt_bias,
        initial_states=initial_state,
        dt_softplus=dt_softplus,
        dt_limit=tuple(dt_limit),
        return_final_states=return_final_state,
    )
    if return_final_state:
        y, final = out
        return y, final.float()
    return out
