"""The one-page SSD (``ssd/minimal.py``) against a loop over frames, and every SSD form against it."""

from __future__ import annotations

import pytest
import torch

from skeleton_mamba.ssd import ssd, ssd_chunked, ssd_quadratic, ssd_recurrence
from skeleton_mamba.ssd.minimal import segsum, ssd_minimal

F64 = torch.float64


def discretised(b=2, L=24, H=4, P=3, G=2, N=5, seed=0):
    """Random SSD inputs: x, Δ, A (X = Δ x and a = Δ A discretised), B, C and an initial state."""
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(b, L, H, P, generator=g, dtype=F64)
    delta = 0.05 + torch.rand(b, L, H, generator=g, dtype=F64)
    A = -(0.5 + 7.5 * torch.rand(H, generator=g, dtype=F64))
    B = torch.randn(b, L, G, N, generator=g, dtype=F64)
    C = torch.randn(b, L, G, N, generator=g, dtype=F64)
    h0 = torch.randn(b, H, P, N, generator=g, dtype=F64)
    return dict(x=x, delta=delta, A=A, B=B, C=C, h0=h0)


def frame_loop(x, delta, A, B, C, h0):
    """h_t = exp(Δ_t A) h_{t-1} + (Δ_t x_t) ⊗ B_t, y_t = h_t C_t: one frame, entry and head at a time."""
    b, L, H, P = x.shape
    G = B.shape[2]
    y = torch.zeros(b, L, H, P, dtype=F64)
    final = torch.zeros_like(h0)
    for i in range(b):
        for h in range(H):
            g = h // (H // G)
            state = h0[i, h].clone()
            for t in range(L):
                state = torch.exp(delta[i, t, h] * A[h]) * state + torch.outer(
                    delta[i, t, h] * x[i, t, h], B[i, t, g]
                )
                y[i, t, h] = state @ C[i, t, g]
            final[i, h] = state
    return y, final


@pytest.mark.parametrize("chunk_size", [1, 4, 8, 24])
@pytest.mark.parametrize("with_state", [False, True])
def test_minimal_equals_the_frame_loop_fp64(chunk_size, with_state):
    inp = discretised()
    h0 = inp["h0"] if with_state else torch.zeros_like(inp["h0"])
    want_y, want_state = frame_loop(inp["x"], inp["delta"], inp["A"], inp["B"], inp["C"], h0)
    X, a = inp["delta"][..., None] * inp["x"], inp["delta"] * inp["A"]
    y, state = ssd_minimal(X, a, inp["B"], inp["C"], chunk_size, h0 if with_state else None)
    torch.testing.assert_close(y, want_y, rtol=1e-10, atol=1e-10)
    torch.testing.assert_close(state, want_state, rtol=1e-10, atol=1e-10)


def test_segsum_entries_are_sums_of_their_own_terms():
    a = torch.tensor([0.5, -1.0, 2.0, -3.0], dtype=F64)
    s = segsum(a)
    for i in range(4):
        for j in range(4):
            want = sum(a[j + 1 : i + 1].tolist()) if i >= j else -torch.inf
            assert s[i, j].item() == pytest.approx(want)


FORMS = {
    "recurrence": lambda **k: ssd_recurrence(**k),
    "chunked Q=8": lambda **k: ssd_chunked(**k, chunk_size=8),
    "chunked Q=7 (padded)": lambda **k: ssd_chunked(**k, chunk_size=7),
    "quadratic": lambda **k: ssd_quadratic(**k),
    "dispatch": lambda **k: ssd(**k),
}


@pytest.mark.parametrize("form", sorted(FORMS))
def test_every_ssd_form_equals_the_minimal_page_fp64(form):
    inp = discretised(L=32, seed=3)
    X, a = inp["delta"][..., None] * inp["x"], inp["delta"] * inp["A"]
    want_y, want_state = ssd_minimal(X, a, inp["B"], inp["C"], 8, inp["h0"])
    args = dict(x=inp["x"], dt=inp["delta"], A=inp["A"], B=inp["B"], C=inp["C"], dt_softplus=False)
    y, state = FORMS[form](**args, initial_state=inp["h0"], return_final_state=True)
    torch.testing.assert_close(y, want_y, rtol=1e-9, atol=1e-9)
    torch.testing.assert_close(state, want_state, rtol=1e-9, atol=1e-9)
    y_alone = FORMS[form](**args)  # no state in or out: the quadratic form's own path
    want_alone, _ = ssd_minimal(X, a, inp["B"], inp["C"], 8)
    torch.testing.assert_close(y_alone, want_alone, rtol=1e-9, atol=1e-9)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="the mamba-ssm kernel needs a CUDA GPU")
def test_the_gpu_forms_equal_the_minimal_page():
    inp = discretised(L=64, H=8, P=16, G=1, N=16, seed=5)
    X, a = inp["delta"][..., None] * inp["x"], inp["delta"] * inp["A"]
    want_y, want_state = ssd_minimal(X, a, inp["B"], inp["C"], 16, inp["h0"])
    cuda = {k: v.float().cuda() for k, v in inp.items()}
    y, state = ssd(
        cuda["x"],
        cuda["delta"],
        cuda["A"],
        cuda["B"],
        cuda["C"],
        dt_softplus=False,
        initial_state=cuda["h0"],
        return_final_state=True,
    )
    torch.testing.assert_close(y.double().cpu(), want_y, rtol=1e-3, atol=1e-3)
    torch.testing.assert_close(state.double().cpu(), want_state, rtol=1e-3, atol=1e-3)


def test_a_length_off_the_chunks_is_refused():
    inp = discretised(L=10)
    with pytest.raises(ValueError, match="not a multiple of chunk_size 4"):
        ssd_minimal(inp["x"], inp["delta"], inp["B"], inp["C"], 4)
