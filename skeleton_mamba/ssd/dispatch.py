"""``ssd``: one entry point choosing between the SSD implementations.

impl="auto": the mamba-ssm Triton kernel when installed and x is on CUDA; else the quadratic form
(:func:`ssd_quadratic`: masked diagonal blocks of about ``quadratic.BLOCK_SIZE`` positions plus the
factorised blocks below the diagonal, no chunk states) when L <= max(chunk_size, QUADRATIC_MAX_LEN)
and no initial/final state is involved, unless the heads are small on a CPU (below); else the chunked form.
impl="torch": the same choice without the kernel. Under ``torch.export`` (and so ONNX export) both
resolve to the exportable form (:func:`ssd_exportable`: no Python loop over sizes), so one graph serves
every batch and length.

QUADRATIC_MAX_LEN is where the quadratic form's O(L²) work starts to cost more than the chunked form's
per-chunk states (on a 2-core CPU at 4 heads, P = N = 64).

Small heads: the quadratic form's work per position grows with its block (about 64 positions) times
P + N, the chunked form's with its chunk Q times P + N plus one state of P·N. With a state of at most
SMALL_STATE entries per head and chunks of at most half a block, the chunked form won at every short
length measured (forward + backward at L = 64, 150 and 256, 4 or 24 heads, one thread, AMD EPYC;
``benchmarks/bench_ssd_dispatch.py``): 1.4x to 2.9x faster than the quadratic form with Q = 16. Larger
heads keep the length rule: at P·N >= 1024 and L <= 150 the quadratic form was ahead or within 6 %
(P = N = 64, L = 150: 1.8x ahead of Q = 32); at L = 256 it was up to 1.4x behind Q = 16 for P·N = 1024,
and even with Q = 64 for P = N = 64. The EgoMusic demo's Temporal Scan (P = 8, N = 16, Q = 16, L = 150)
has small heads. The rule was measured on CPUs only; on CUDA (without the kernel) the length rule decides
alone.
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.chunked import ssd_chunked
from skeleton_mamba.ssd.discretize import NO_DT_LIMIT
from skeleton_mamba.ssd.exportable import ssd_exportable
from skeleton_mamba.ssd.kernel import kernel_available, ssd_kernel
from skeleton_mamba.ssd.precision import full_precision
from skeleton_mamba.ssd.quadratic import BLOCK_SIZE as QUADRATIC_BLOCK_SIZE
from skeleton_mamba.ssd.quadratic import ssd_quadratic
from skeleton_mamba.ssd.recurrence import ssd_recurrence

QUADRATIC_MAX_LEN = 256
SMALL_STATE = 256  # P·N per head at or below which chunks of at most half a quadratic block are faster
IMPLS = ("auto", "torch", "recurrence", "chunked", "quadratic", "kernel", "exportable")


def choose_impl(
    x: torch.Tensor, chunk_size: int, stateful: bool, impl: str = "auto", state_size: int | None = None
) -> str:
    """The concrete implementation ``ssd`` runs for ``impl`` ("auto"/"torch" resolved) on x (b, L, H, P)
    with states of ``state_size`` N (None: treated as large)."""
    if impl not in IMPLS:
        raise ValueError(f"ssd: impl must be one of {IMPLS}, got {impl!r}")
    if impl in ("auto", "torch") and torch.compiler.is_exporting():
        return "exportable"
    if impl == "auto" and kernel_available(x):
        return "kernel"
    if impl in ("auto", "torch"):
        length = x.shape[1]
        short = length <= max(chunk_size, QUADRATIC_MAX_LEN)
        small_heads = (
            x.device.type == "cpu" and state_size is not None and x.shape[-1] * state_size <= SMALL_STATE
        )
        # Measured eagerly; compiled code takes the quadratic form, which inductor traces (the chunked
        # form's ChunkScan runs eagerly, a graph break that compile_for_inference's fullgraph refuses).
        chunks_pay = (
            small_heads
            and chunk_size < length
            and chunk_size <= QUADRATIC_BLOCK_SIZE // 2
            and not torch.compiler.is_compiling()
        )
        return "quadratic" if short and not stateful and not chunks_pay else "chunked"
    return impl


@full_precision
def ssd(
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
    impl: str = "auto",
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """Structured state-space duality (Mamba-2) per head.

    h_t = exp(Δ_t A) h_{t-1} + (Δ_t x_t) ⊗ B_t,  y_t = h_t C_t + D ⊙ x_t,
    Δ = clamp(softplus(dt + dt_bias), dt_limit) in fp32.

    Args:
        x: (b, L, H, P).
        dt: (b, L, H) raw step sizes.
        A: (H,) negative continuous decay per head (A = -exp(A_log)).
        B: (b, L, G, N) input projections, H % G == 0; head h reads group h // (H // G).
        C: (b, L, G, N) output projections, grouped as B.
        D: (H,) or (H, P) skip weights, or ``None``.
        dt_bias: (H,) or ``None``.
        dt_softplus: apply the softplus to dt + dt_bias (see above).
        dt_limit: the (min, max) clamp of Δ (see above).
        initial_state: (b, H, P, N) or ``None`` (zeros).
        return_final_state: also return the final state (b, H, P, N) in fp32.
        chunk_size: chunk length of the chunked form (and of the kernel).
        impl: "auto" | "torch" | "recurrence" | "chunked" | "quadratic" | "kernel" | "exportable".

    Returns:
        y (b, L, H, P) in x's dtype, or (y, final_state) when ``return_final_state``.

    Examples:
        >>> import torch
        >>> from skeleton_mamba import ssd
        >>> from skeleton_mamba.ssd import ssd_recurrence
        >>> g = torch.Generator().manual_seed(0)
        >>> x = torch.randn(1, 100, 2, 4, generator=g, dtype=torch.float64)  # (batch, L, heads, headdim)
        >>> dt = torch.rand(1, 100, 2, generator=g, dtype=torch.float64)  # (batch, L, heads)
        >>> A = -torch.rand(2, generator=g, dtype=torch.float64)  # (heads,)
        >>> B, C = torch.randn(2, 1, 100, 1, 8, generator=g, dtype=torch.float64)  # (batch, L, groups, N)
        >>> torch.allclose(ssd(x, dt, A, B, C), ssd_recurrence(x, dt, A, B, C))  # = the recurrence
        True
    """
    kwargs = dict(
        D=D,
        dt_bias=dt_bias,
        dt_softplus=dt_softplus,
        dt_limit=dt_limit,
        initial_state=initial_state,
        return_final_state=return_final_state,
    )
    stateful = initial_state is not None or return_final_state
    chosen = choose_impl(x, chunk_size, stateful, impl, state_size=B.shape[-1])
    if chosen == "kernel":
        return ssd_kernel(x, dt, A, B, C, chunk_size=chunk_size, **kwargs)
    if chosen == "chunked":
        return ssd_chunked(x, dt, A, B, C, chunk_size=chunk_size, **kwargs)
    if chosen == "exportable":
        return ssd_exportable(x, dt, A, B, C, **kwargs)
    if chosen == "quadratic":
        return ssd_quadratic(x, dt, A, B, C, **kwargs)
    return ssd_recurrence(x, dt, A, B, C, **kwargs)
