"""The sequential SSD recurrence ([Mamba-2] SSD recurrence): the test oracle for the matrix forms.

h_t = exp(Δ_t A) h_{t-1} + (Δ_t x_t) ⊗ B_t,   y_t = h_t C_t + D ⊙ x_t.

One Python step per time step, so only for tests and tiny inputs. fp64 inputs are computed in fp64.
:func:`recurrence_step` is the one step, also taken by :meth:`~skeleton_mamba.mixer.Mamba2Mixer.step` for
a stream's next token.
"""

from __future__ import annotations

import torch

from skeleton_mamba.ssd.discretize import NO_DT_LIMIT, apply_skip, check_inputs, compute_dtype, discretize_dt
from skeleton_mamba.ssd.precision import full_precision


def recurrence_step(
    h: torch.Tensor,
    decay: torch.Tensor,
    xd: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    out: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """One step: h' = exp(Δ A) h + (Δ x) ⊗ B and y = h' C, one product per (sequence, B/C group).

    Args:
        h: (b, H, P, N) the state before the step.
        decay: (b, H) exp(Δ A).
        xd: (b, H, P) Δ x.
        B: (b, G, N) the input projections; head h reads group h // (H // G).
        C: (b, G, N) the output projections, grouped as B.
        out: optional (b, H, P, N) contiguous tensor for h' (may be ``h`` itself, then updated in place).

    Returns:
        h' (b, H, P, N) and y (b, H, P) (without the skip D ⊙ x).

    Examples:
        >>> import torch
        >>> h, B, C = torch.zeros(1, 2, 3, 4), torch.ones(1, 1, 4), torch.ones(1, 1, 4)
        >>> h, y = recurrence_step(h, torch.full((1, 2), 0.5), torch.ones(1, 2, 3), B, C)
        >>> y[0, 0].tolist()  # h' = 0.5 * 0 + 1 ⊗ 1, y = Σ_n h'
        [4.0, 4.0, 4.0]
    """
    b, H, P, N = h.shape
    G = B.shape[1]
    decayed = (h * decay[:, :, None, None]).view(b * G, H // G * P, N)
    target = None if out is None else out.view(b * G, H // G * P, N)
    new = torch.baddbmm(decayed, xd.reshape(b * G, -1, 1), B.reshape(b * G, 1, N), out=target)
    y = torch.bmm(new, C.reshape(b * G, N, 1))
    return new.view(b, H, P, N), y.view(b, H, P)


@full_precision
def ssd_recurrence(
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
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """SSD by the step-by-step recurrence.

    Args:
        x: (b, L, H, P) inputs.
        dt: (b, L, H) raw step sizes (see :func:`discretize_dt`).
        A: (H,) negative continuous decay per head.
        B: (b, L, G, N) input projections; head h reads group h // (H // G).
        C: (b, L, G, N) output projections, grouped as B.
        D: (H,) or (H, P) skip, or ``None``.
        dt_bias: the discretisation of Δ: bias added to dt.
        dt_softplus: the discretisation of Δ: softplus of dt + dt_bias.
        dt_limit: the discretisation of Δ: its (min, max) clamp.
        initial_state: (b, H, P, N) state before the first step, or ``None`` (zeros).
        return_final_state: also return the state after the last step.

    Returns:
        y (b, L, H, P) in x's dtype, and the final state (b, H, P, N) (fp32, fp64 for fp64 input)
        when ``return_final_state``.
    """
    check_inputs(x, dt, A, B, C, D, dt_bias, initial_state)
    b, L, H, P = x.shape
    N = B.shape[3]
    ct = compute_dtype(x)
    delta = discretize_dt(dt, dt_bias, dt_softplus, dt_limit, ct)  # (b, L, H)
    decay = torch.exp(delta * A.to(ct))  # (b, L, H)
    xd = x.to(ct) * delta[..., None]  # (b, L, H, P)
    Bc, Cc = B.to(ct), C.to(ct)
    h = x.new_zeros((b, H, P, N), dtype=ct) if initial_state is None else initial_state.to(ct)
    ys = []
    for t in range(L):
        h, y_t = recurrence_step(h, decay[:, t], xd[:, t], Bc[:, t], Cc[:, t])
        ys.append(y_t)
    y = torch.stack(ys, dim=1) if ys else x.new_zeros((b, 0, H, P), dtype=ct)
    y = apply_skip(y, x, D).to(x.dtype)
    return (y, h) if return_final_state else y
