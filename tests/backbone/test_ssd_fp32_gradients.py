"""fp32 gradients of the SSD matrix forms against the float64 truth, measured against the fp32 recurrence.

For every argument g of ``ssd`` (x, dt, A, B, C, D, dt_bias, initial state) the error of a form is the
relative norm error of its fp32 gradient against the float64 truth,

    err(g) = ||g_fp32 - g_true||_2 / ||g_true||_2   (norms over all entries of g, in float64),

where the truth is autograd through the float64 recurrence (:func:`ssd_recurrence`) and the loss is
Σ y ⊙ gy (+ Σ S_final ⊙ gS when the final state is returned) with fixed random gy, gS. The yardstick is the
same error of autograd through the fp32 recurrence; every form must stay within ``RATIO`` times it.
"""

from __future__ import annotations

import pytest
import torch

from skeleton_mamba.runtime.compiling import inductor_unavailable
from skeleton_mamba.ssd import ssd_chunked, ssd_quadratic, ssd_recurrence

F64 = torch.float64
RATIO = 4.0
# An error below one fp32 rounding (2^-24) is noise in the yardstick itself, not a loss of accuracy.
FLOOR = 2.0**-24
ARGS = ("x", "dt", "A", "B", "C", "D", "dt_bias", "initial_state")


def make_inputs(L: int, decay: str, seed: int = 0) -> dict[str, torch.Tensor]:
    """float64 inputs, b = 2, H = 8 heads in two B/C groups (P = N = 16).

    Eight heads make the yardstick of A's gradient (one number per head) a norm over eight values, not
    the luck of one or two.

    decay "slow": |Δ·A| ≈ 0.01 per step (Δ ≈ 0.01, A ≈ -1); "fast": |Δ·A| ≈ 2 per step (Δ ≈ 0.5, A ≈ -4).
    """
    g = torch.Generator().manual_seed(seed)
    b, H, P, G, N = 2, 8, 16, 2, 16
    r = lambda *s: torch.randn(*s, generator=g, dtype=F64)  # noqa: E731
    delta0, a_mag = (0.01, 1.0) if decay == "slow" else (0.5, 4.0)
    d0 = torch.full((H,), delta0, dtype=F64)
    return dict(
        x=r(b, L, H, P),
        dt=0.3 * r(b, L, H),
        A=-a_mag * (0.8 + 0.4 * torch.rand(H, generator=g, dtype=F64)),
        B=r(b, L, G, N),
        C=r(b, L, G, N),
        D=r(H),
        dt_bias=d0 + torch.log(-torch.expm1(-d0)),
        initial_state=r(b, H, P, N),
    )


def gradients(fn, inp: dict[str, torch.Tensor], dtype: torch.dtype, stateful: bool, seed: int = 1):
    """Autograd gradients of Σ y ⊙ gy (+ Σ final ⊙ gS) w.r.t. every argument, returned in float64."""
    names = [k for k in inp if stateful or k != "initial_state"]
    leaves = {k: inp[k].to(dtype, copy=True).requires_grad_(True) for k in names}
    out = fn(**leaves, return_final_state=stateful)
    g = torch.Generator().manual_seed(seed)
    y, final = out if stateful else (out, None)
    loss = (y.double() * torch.randn(y.shape, generator=g, dtype=F64)).sum()
    if final is not None:
        loss = loss + (final.double() * torch.randn(final.shape, generator=g, dtype=F64)).sum()
    loss.backward()
    return {k: v.grad.double() for k, v in leaves.items()}


def rel_err(g: torch.Tensor, truth: torch.Tensor) -> float:
    return float((g - truth).norm() / truth.norm())


_CACHE: dict = {}


def reference(L: int, decay: str, stateful: bool):
    """(inputs, float64 truth, fp32 recurrence errors) for one setting, computed once per session."""
    key = (L, decay, stateful)
    if key not in _CACHE:
        inp = make_inputs(L, decay)
        truth = gradients(ssd_recurrence, inp, F64, stateful)
        rec = gradients(ssd_recurrence, inp, torch.float32, stateful)
        _CACHE[key] = inp, truth, {k: rel_err(rec[k], truth[k]) for k in truth}
    return _CACHE[key]


def _compiled(form):
    """The form under ``torch.compile`` (inductor): IntraChunk traced into the graph, ChunkScan eager."""
    compiled = torch.compile(form, backend="inductor", dynamic=False)
    return lambda **kw: compiled(**kw)


def _chunked(**kw):
    return ssd_chunked(**kw, chunk_size=64)


FORMS = {
    # the quadratic form: diagonal blocks of 64 and the factorised blocks below them, no states
    "quadratic": (ssd_quadratic, False),
    # the quadratic form with states: the whole sequence as one chunk of the chunked form
    "quadratic_state": (ssd_quadratic, True),
    "chunked": (_chunked, False),
    "chunked_state": (_chunked, True),
    "compiled_quadratic": (_compiled(ssd_quadratic), False),
    "compiled_chunked_state": (_compiled(_chunked), True),
}
EAGER = [f for f in FORMS if not f.startswith("compiled")]
COMPILED = [f for f in FORMS if f.startswith("compiled")]
needs_inductor = pytest.mark.skipif(inductor_unavailable() is not None, reason=str(inductor_unavailable()))


def check(L: int, decay: str, form: str) -> None:
    fn, stateful = FORMS[form]
    inp, truth, rec_err = reference(L, decay, stateful)
    got = gradients(fn, inp, torch.float32, stateful)
    errs = {k: rel_err(got[k], truth[k]) for k in truth}
    bad = {k: (errs[k], rec_err[k]) for k in truth if errs[k] > RATIO * max(rec_err[k], FLOOR)}
    assert not bad, f"{form} L={L} {decay}: (form error, fp32 recurrence error) per argument {bad}"


@pytest.mark.parametrize("form", EAGER)
@pytest.mark.parametrize("decay", ["slow", "fast"])
@pytest.mark.parametrize("L", [150, 1200])
def test_fp32_gradients_within_4x_of_recurrence(L, decay, form):
    check(L, decay, form)


@needs_inductor
@pytest.mark.parametrize("form", COMPILED)
@pytest.mark.parametrize("decay", ["slow", "fast"])
def test_compiled_fp32_gradients_within_4x_of_recurrence(decay, form):
    check(150, decay, form)


@pytest.mark.slow
@pytest.mark.parametrize("form", EAGER + COMPILED)
@pytest.mark.parametrize("decay", ["slow", "fast"])
@pytest.mark.parametrize("L", [1200, 4800])
def test_fp32_gradients_within_4x_of_recurrence_long(L, decay, form):
    if form in COMPILED and inductor_unavailable() is not None:
        pytest.skip(str(inductor_unavailable()))
    if L == 1200 and form in EAGER:
        pytest.skip("run by test_fp32_gradients_within_4x_of_recurrence")
    check(L, decay, form)
