"""Non-finite inputs in the matrix forms of the SSD: confined to the steps at and after them.

The recurrence h_t = exp(Δ_t A) h_{t-1} + (Δ_t x_t) ⊗ B_t, y_t = h_t C_t + D ⊙ x_t carries a NaN or Inf
met at step k into steps k, k+1, ... only. The matrix forms multiply whole blocks: a zero of the causal
decay mask times a NaN is NaN, so a NaN at step k reached every earlier step of its chunk (quadratic
form: of the sequence), and through the chunk-state products the earlier chunks too. With right
padding that lets garbage in the padding reach the valid steps.

:func:`confine_non_finite` wraps a matrix form so that it agrees with the recurrence:

- fast path: one finiteness reduction over x, dt, B and C per call; when all are finite the form runs
  unchanged;
- otherwise the form runs on inputs whose non-finite entries are replaced by 0, and the outputs the
  recurrence makes non-finite are set to NaN. With Δ the discretised step (:func:`discretize_dt`; a
  raw ``dt = -inf`` gives Δ = 0, finite, as in the recurrence), head h reading B/C group g(h):

  - y[t, h, p] for every t ≥ k where x[k, h, p], Δ[k, h] or any B[k, g(h), :] is non-finite;
  - y[t, h, :] where any C[t, g(h), :] is non-finite (that step only);
  - final state [h, p, n] where x[k, h, p], Δ[k, h] or B[k, g(h), n] is non-finite for some k.

  A non-finite A, D, dt_bias or initial state (parameters and state, not data) is passed on unchanged.
  Where the recurrence would give ±Inf the wrapper gives NaN; the finite outputs are the same.

Under ``torch.compile`` the data-dependent choice would break the graph at every call, and the second
path made unconditional cost more than the whole compiled step (its ``cummax``), so compiled code runs
the form unchecked: non-finite inputs are NOT confined there (they reach the earlier steps of their
block). Compiled inference is meant for finite inputs such as diffusion sampling.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import torch

from skeleton_mamba.ssd.discretize import NO_DT_LIMIT, check_inputs, compute_dtype, discretize_dt


def _zero_non_finite(t: torch.Tensor) -> torch.Tensor:
    return torch.where(torch.isfinite(t), t, torch.zeros((), dtype=t.dtype, device=t.device))


def _reached(step: torch.Tensor) -> torch.Tensor:
    """(b, L, ...) bool -> True from the first True along L on."""
    return torch.cummax(step.to(torch.uint8), dim=1).values.bool()


def inputs_finite(x: torch.Tensor, dt: torch.Tensor, B: torch.Tensor, C: torch.Tensor) -> bool:
    """Whether every entry of the per-step inputs is finite: the fast path's only cost (one sync on CUDA).

    One sum per tensor, accumulated in fp32 (fp64 for fp64): a NaN or Inf makes the sum non-finite. A sum
    that overflows although every entry is finite (beyond 3e38) only sends the call down the slow path,
    which is exact too. On CPU a sum is several times faster than ``torch.isfinite(t).all()``.
    """
    total = sum(t.sum(dtype=compute_dtype(t)) for t in (x, dt, B, C))
    return bool(torch.isfinite(total))


def confine_non_finite(form: Callable) -> Callable:
    """Decorate an SSD form ``form(x, dt, A, B, C, *, D, dt_bias, dt_softplus, dt_limit, initial_state,
    return_final_state, **kw)`` so that non-finite inputs behave as in the recurrence (module docstring)."""

    @functools.wraps(form)
    def confined(x, dt, A, B, C, *, D=None, dt_bias=None, dt_softplus=True, dt_limit=NO_DT_LIMIT,
                 initial_state=None, return_final_state=False, **kwargs):  # fmt: skip
        kwargs.update(D=D, dt_bias=dt_bias, dt_softplus=dt_softplus, dt_limit=dt_limit,
                      initial_state=initial_state, return_final_state=return_final_state)  # fmt: skip
        if torch.compiler.is_compiling() or inputs_finite(x, dt, B, C):
            return form(x, dt, A, B, C, **kwargs)
        check_inputs(x, dt, A, B, C, D, dt_bias, initial_state)
        R = x.shape[2] // B.shape[2]  # heads per B/C group
        delta = discretize_dt(dt, dt_bias, dt_softplus, dt_limit, compute_dtype(x))
        x_bad, delta_bad, B_bad = ~torch.isfinite(x), ~torch.isfinite(delta), ~torch.isfinite(B)
        C_bad = (~torch.isfinite(C)).any(-1).repeat_interleave(R, dim=2)  # (b, L, H)
        step = x_bad | (delta_bad | B_bad.any(-1).repeat_interleave(R, dim=2))[..., None]  # (b, L, H, P)
        y_bad = _reached(step) | C_bad[..., None]
        clean_dt = torch.where(delta_bad, torch.zeros((), dtype=dt.dtype, device=dt.device), dt)
        out = form(_zero_non_finite(x), clean_dt, A, _zero_non_finite(B), _zero_non_finite(C), **kwargs)
        y, final = out if return_final_state else (out, None)
        y = y.masked_fill(y_bad, float("nan"))
        if final is None:
            return y
        B_any = B_bad.any(1).repeat_interleave(R, dim=1)  # (b, H, N)
        final_bad = (x_bad.any(1) | delta_bad.any(1)[..., None])[..., None] | B_any[:, :, None, :]
        return y, final.masked_fill(final_bad, float("nan"))

    return confined
