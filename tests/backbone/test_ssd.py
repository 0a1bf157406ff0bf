"""SSD: the recurrence against a loop-built matrix form; chunked/quadratic against the recurrence."""

from __future__ import annotations

import importlib.machinery
import itertools
import math
import sys
import types

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from skeleton_mamba.ssd import kernel as kernel_mod
from skeleton_mamba.ssd import ssd, ssd_chunked, ssd_quadratic, ssd_recurrence
from skeleton_mamba.ssd.below_diagonal import below_diagonal
from skeleton_mamba.ssd.dispatch import choose_impl
from skeleton_mamba.ssd.minimal import segsum
from skeleton_mamba.ssd.segsum import decay_mask

F64 = torch.float64


def make_inputs(b, L, H, P, G, N, dtype=F64, seed=0, d_shape="h"):
    """Random SSD inputs in the Mamba-2 regime (A in [-8, -0.5], dt raw around the dt_bias)."""
    g = torch.Generator().manual_seed(seed)
    r = lambda *s: torch.randn(*s, generator=g, dtype=F64)  # noqa: E731
    inp = dict(
        x=r(b, L, H, P),
        dt=r(b, L, H),
        A=-(0.5 + 7.5 * torch.rand(H, generator=g, dtype=F64)),
        B=r(b, L, G, N),
        C=r(b, L, G, N),
        D=r(H) if d_shape == "h" else r(H, P),
        dt_bias=r(H) - 1.0,
        initial_state=r(b, H, P, N),
    )
    return {k: v.to(dtype) for k, v in inp.items()}


def naive_matrix_form(x, dt, A, B, C, D, dt_bias, h0):
    """y = (M ∘ C Bᵀ)(Δ ∘ x) + D x (+ the initial-state term), built entry by entry with Python loops.

    M_ij = Π_{k=j+1}^{i} a_k (a_k = exp(Δ_k A)); Δ = log(1 + exp(dt + dt_bias)) with math.* floats.
    Returns y (b, L, H, P) and the final state (b, H, P, N) as nested computations in float64.
    """
    b, L, H, P = x.shape
    G, N = B.shape[2], B.shape[3]
    y = torch.zeros(b, L, H, P, dtype=F64)
    final = torch.zeros(b, H, P, N, dtype=F64)
    for bi in range(b):
        for h in range(H):
            g = h // (H // G)
            delta = [math.log1p(math.exp(float(dt[bi, t, h] + dt_bias[h]))) for t in range(L)]
            a = [math.exp(delta[t] * float(A[h])) for t in range(L)]
            for i in range(L):
                for j in range(i + 1):
                    m = math.prod(a[j + 1 : i + 1])
                    cb = float(C[bi, i, g] @ B[bi, j, g])
                    y[bi, i, h] += m * cb * delta[j] * x[bi, j, h]
                y[bi, i, h] += math.prod(a[: i + 1]) * (h0[bi, h] @ C[bi, i, g]) + D[h] * x[bi, i, h]
            final[bi, h] = math.prod(a) * h0[bi, h]
            for j in range(L):
                final[bi, h] += math.prod(a[j + 1 :]) * delta[j] * torch.outer(x[bi, j, h], B[bi, j, g])
    return y, final


def test_recurrence_equals_loop_built_matrix_form():
    inp = make_inputs(2, 7, 4, 3, 2, 5, seed=1)
    y_ref, f_ref = naive_matrix_form(
        *(inp[k] for k in ("x", "dt", "A", "B", "C", "D", "dt_bias", "initial_state"))
    )
    y, f = ssd_recurrence(**inp, return_final_state=True)
    torch.testing.assert_close(y, y_ref, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(f, f_ref, rtol=1e-12, atol=1e-12)


def test_decay_mask_matches_stable_segsum_and_loops():
    a = -torch.rand(3, 9, dtype=F64) * 4
    mask = decay_mask(a.cumsum(-1))
    torch.testing.assert_close(mask, segsum(a).exp(), rtol=1e-12, atol=0)
    for i in range(9):
        for j in range(9):
            expected = math.exp(float(a[1, j + 1 : i + 1].sum())) if i >= j else 0.0
            assert mask[1, i, j].item() == pytest.approx(expected, rel=1e-12, abs=0)
    # fp32: the cumsum-difference mask stays within 1e-5 relative of the fp64 stable mask for
    # chunk-length sums (|cs| up to 64 * 2 = 128).
    a32 = -torch.rand(4, 64) * 2
    rel = (decay_mask(a32.cumsum(-1)).double() - segsum(a32.double()).exp()).abs()
    assert (rel / segsum(a32.double()).exp().clamp_min(1e-30)).max() < 1e-5


def run_all(fn, inp, **kw):
    return fn(**inp, return_final_state=True, **kw)


SHAPES = [  # (b, L, H, P, G, N, chunk)
    (1, 1, 1, 1, 1, 1, 4),
    (2, 5, 2, 3, 1, 4, 8),
    (2, 16, 4, 2, 2, 3, 8),
    (3, 23, 6, 4, 3, 2, 8),
    (1, 40, 2, 5, 1, 6, 16),
    (2, 37, 4, 3, 4, 5, 5),
]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("fn", ["chunked", "quadratic"])
def test_matrix_forms_equal_recurrence_fp64(shape, fn):
    b, L, H, P, G, N, Q = shape
    inp = make_inputs(b, L, H, P, G, N, seed=L, d_shape="hp" if H % 2 else "h")
    y_ref, f_ref = run_all(ssd_recurrence, inp)
    y, f = run_all(ssd_chunked, inp, chunk_size=Q) if fn == "chunked" else run_all(ssd_quadratic, inp)
    torch.testing.assert_close(y, y_ref, rtol=1e-10, atol=1e-10)
    torch.testing.assert_close(f, f_ref, rtol=1e-10, atol=1e-10)


@given(
    b=st.integers(1, 2),
    L=st.integers(1, 30),
    H=st.sampled_from([1, 2, 4]),
    P=st.integers(1, 4),
    G=st.sampled_from([1, 2]),
    N=st.integers(1, 4),
    Q=st.integers(1, 12),
    use_d=st.booleans(),
    use_bias=st.booleans(),
    use_h0=st.booleans(),
    final=st.booleans(),
)
@settings(max_examples=25, deadline=None)
def test_optional_arguments_hypothesis(b, L, H, P, G, N, Q, use_d, use_bias, use_h0, final):
    G = min(G, H)
    inp = make_inputs(b, L, H, P, G, N, seed=7)
    inp["D"] = inp["D"] if use_d else None
    inp["dt_bias"] = inp["dt_bias"] if use_bias else None
    inp["initial_state"] = inp["initial_state"] if use_h0 else None
    ref = ssd_recurrence(**inp, return_final_state=final)
    for out in (
        ssd_chunked(**inp, return_final_state=final, chunk_size=Q),
        ssd_quadratic(**inp, return_final_state=final),
        ssd(**inp, return_final_state=final, chunk_size=Q),
    ):
        if final:
            torch.testing.assert_close(out[1], ref[1], rtol=1e-10, atol=1e-10)
            out, expected = out[0], ref[0]
        else:
            expected = ref
        torch.testing.assert_close(out, expected, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("L,Q", [(150, 64), (150, 150), (40, 64), (6, 64), (200, 48)])
def test_fp32_within_1e5_of_fp64_recurrence(L, Q):
    inp = make_inputs(2, L, 4, 8, 1, 16, seed=3)
    y_ref, f_ref = run_all(ssd_recurrence, inp)
    inp32 = {k: v.float() for k, v in inp.items()}
    for y, f in (run_all(ssd_chunked, inp32, chunk_size=Q), run_all(ssd_quadratic, inp32)):
        assert y.dtype == torch.float32 and f.dtype == torch.float32
        assert (y.double() - y_ref).abs().max() <= 1e-5 * y_ref.abs().max()
        assert (f.double() - f_ref).abs().max() <= 1e-5 * f_ref.abs().max()


GRAD_NAMES = ["x", "dt", "A", "B", "C", "D", "dt_bias", "initial_state"]


def grads(fn, inp, **kw):
    leaves = {k: v.detach().clone().requires_grad_(True) for k, v in inp.items()}
    y, f = fn(**leaves, return_final_state=True, **kw)
    g = torch.Generator().manual_seed(11)
    loss = (y * torch.randn(y.shape, generator=g, dtype=y.dtype)).sum() + (
        f * torch.randn(f.shape, generator=g, dtype=f.dtype)
    ).sum()
    loss.backward()
    return {k: leaves[k].grad for k in GRAD_NAMES}


@pytest.mark.parametrize("shape", [(2, 13, 4, 3, 2, 5, 4), (1, 20, 2, 4, 1, 3, 20), (2, 9, 3, 2, 3, 2, 16)])
@pytest.mark.parametrize("fn", ["chunked", "quadratic"])
def test_gradients_equal_recurrence_fp64(shape, fn):
    b, L, H, P, G, N, Q = shape
    inp = make_inputs(b, L, H, P, G, N, seed=5, d_shape="hp")
    ref = grads(ssd_recurrence, inp)
    got = grads(ssd_chunked, inp, chunk_size=Q) if fn == "chunked" else grads(ssd_quadratic, inp)
    for k in GRAD_NAMES:
        assert got[k] is not None, k
        torch.testing.assert_close(got[k], ref[k], rtol=1e-9, atol=1e-9, msg=lambda m, k=k: f"grad {k}: {m}")


def test_gradients_without_state_or_skip():
    inp = make_inputs(2, 11, 2, 3, 1, 4, seed=8)
    for k in ("D", "initial_state"):
        inp[k] = None
    for fn, kw in ((ssd_chunked, {"chunk_size": 4}), (ssd_quadratic, {})):
        leaves = [
            {k: v.clone().requires_grad_(True) if v is not None else None for k, v in inp.items()}
            for _ in range(2)
        ]
        ssd_recurrence(**leaves[0]).pow(2).sum().backward()
        fn(**leaves[1], **kw).pow(2).sum().backward()
        for k in ("x", "dt", "A", "B", "C", "dt_bias"):
            torch.testing.assert_close(leaves[1][k].grad, leaves[0][k].grad, rtol=1e-9, atol=1e-9)


def test_dt_limit_and_no_softplus():
    inp = make_inputs(1, 10, 2, 2, 1, 3, seed=2)
    inp["dt"], inp["dt_bias"] = inp["dt"].abs(), inp["dt_bias"].abs()  # Δ >= 0 without the softplus
    limits = (
        {"dt_limit": (0.2, 0.5)},
        {"dt_softplus": False},
        {"dt_softplus": False, "dt_limit": (0.3, 1.0)},
    )
    for kw in limits:
        ref = ssd_recurrence(**inp, **kw)
        torch.testing.assert_close(ssd_chunked(**inp, chunk_size=3, **kw), ref, rtol=1e-10, atol=1e-10)
        torch.testing.assert_close(ssd_quadratic(**inp, **kw), ref, rtol=1e-10, atol=1e-10)
    # the clamp really acts: Δ = 0.2 everywhere once dt + bias is very negative
    low = dict(inp, dt=torch.full_like(inp["dt"], -30.0), dt_bias=None, D=None, initial_state=None)
    y = ssd_recurrence(**low, dt_limit=(0.2, 0.5))
    const = dict(low, dt=torch.full_like(inp["dt"], 0.2))
    torch.testing.assert_close(y, ssd_recurrence(**const, dt_softplus=False), rtol=1e-12, atol=1e-12)


def test_dtype_is_preserved_and_state_is_fp32():
    inp = {k: v.to(torch.bfloat16) for k, v in make_inputs(1, 9, 2, 4, 1, 4).items()}
    y, f = ssd(**inp, return_final_state=True)
    assert y.dtype == torch.bfloat16 and f.dtype == torch.float32


def test_bad_shapes_raise():
    inp = make_inputs(1, 5, 4, 2, 2, 3)
    with pytest.raises(ValueError, match="dt must be"):
        ssd(**dict(inp, dt=inp["dt"][..., :3]))
    with pytest.raises(ValueError, match="cannot be split"):
        ssd(**dict(inp, B=inp["B"].repeat(1, 1, 2, 1)[:, :, :3], C=inp["C"].repeat(1, 1, 2, 1)[:, :, :3]))
    with pytest.raises(ValueError, match="initial_state"):
        ssd(**dict(inp, initial_state=inp["initial_state"][:, :2]))
    with pytest.raises(ValueError, match="impl must be"):
        ssd(**inp, impl="fast")


def test_auto_dispatch_on_cpu():
    x = torch.zeros(1, 40, 2, 2)
    assert choose_impl(x, 64, stateful=False) == "quadratic"
    assert choose_impl(x, 64, stateful=True) == "chunked"
    assert choose_impl(torch.zeros(1, 256, 2, 2), 64, stateful=False) == "quadratic"
    assert choose_impl(torch.zeros(1, 257, 2, 2), 64, stateful=False) == "chunked"
    assert choose_impl(torch.zeros(1, 300, 2, 2), 512, stateful=False) == "quadratic"
    assert choose_impl(x, 64, stateful=False, impl="recurrence") == "recurrence"
    inp = make_inputs(2, 70, 2, 3, 1, 4)
    ref = ssd_recurrence(**inp)
    for impl in ("auto", "torch", "chunked", "quadratic", "recurrence"):
        torch.testing.assert_close(ssd(**inp, impl=impl), ref, rtol=1e-10, atol=1e-10)


def test_auto_dispatch_runs_small_heads_in_chunks():
    """Heads with at most SMALL_STATE state entries (P·N) take chunks of at most half a quadratic block."""
    small = torch.zeros(1, 150, 4, 8)  # P = 8
    assert choose_impl(small, 16, stateful=False, state_size=16) == "chunked"  # the demo's Temporal Scan
    assert choose_impl(small, 32, stateful=False, state_size=32) == "chunked"  # P·N = 256
    assert choose_impl(small, 64, stateful=False, state_size=16) == "quadratic"  # chunks as long as a block
    assert choose_impl(small, 16, stateful=False, state_size=64) == "quadratic"  # P·N = 512
    assert choose_impl(torch.zeros(1, 16, 4, 8), 16, stateful=False, state_size=16) == "quadratic"  # L <= Q
    assert choose_impl(small, 16, stateful=False) == "quadratic"  # state size not given: the length rule
    inp = make_inputs(2, 70, 2, 8, 1, 16)
    del inp["initial_state"]
    ref = ssd_recurrence(**inp)
    for impl in ("auto", "torch"):
        torch.testing.assert_close(ssd(**inp, chunk_size=16, impl=impl), ref, rtol=1e-10, atol=1e-10)


def install_fake_mamba_ssm(monkeypatch, calls):
    """Put a fake ``mamba_ssm.ops.triton.ssd_combined`` into sys.modules that records its arguments."""
    names = ["mamba_ssm", "mamba_ssm.ops", "mamba_ssm.ops.triton", "mamba_ssm.ops.triton.ssd_combined"]
    for name in names:
        mod = types.ModuleType(name)
        mod.__spec__ = importlib.machinery.ModuleSpec(name, loader=None)
        monkeypatch.setitem(sys.modules, name, mod)

    def mamba_chunk_scan_combined(
        x,
        dt,
        A,
        B,
        C,
        chunk_size,
        D=None,
        z=None,
        dt_bias=None,
        initial_states=None,
        seq_idx=None,
        cu_seqlens=None,
        dt_softplus=False,
        dt_limit=(0.0, float("inf")),
        return_final_states=False,
        return_varlen_states=False,
    ):
        calls.append(
            dict(
                chunk_size=chunk_size,
                D=D,
                z=z,
                dt_bias=dt_bias,
                initial_states=initial_states,
                dt_softplus=dt_softplus,
                dt_limit=dt_limit,
                return_final_states=return_final_states,
            )
        )
        return ssd_recurrence(
            x,
            dt,
            A,
            B,
            C,
            D=D,
            dt_bias=dt_bias,
            dt_softplus=dt_softplus,
            dt_limit=dt_limit,
            initial_state=initial_states,
            return_final_state=return_final_states,
        )

    sys.modules[names[-1]].mamba_chunk_scan_combined = mamba_chunk_scan_combined


def test_kernel_argument_mapping_with_fake_module(monkeypatch):
    calls = []
    install_fake_mamba_ssm(monkeypatch, calls)
    monkeypatch.setattr(kernel_mod, "is_cuda", lambda t: True)
    inp = make_inputs(1, 12, 2, 3, 1, 4)
    x = inp["x"]
    assert choose_impl(x, 64, stateful=False) == "kernel"
    assert choose_impl(x, 64, stateful=False, impl="torch") == "quadratic"
    y, f = ssd(**inp, return_final_state=True, chunk_size=32, dt_limit=(0.0, 5.0))
    call = calls[-1]
    assert call["chunk_size"] == 32 and call["z"] is None and call["dt_softplus"] is True
    assert call["dt_limit"] == (0.0, 5.0) and call["return_final_states"] is True
    assert call["D"] is inp["D"] and call["dt_bias"] is inp["dt_bias"]
    assert call["initial_states"] is inp["initial_state"]
    y_ref, f_ref = ssd_recurrence(**inp, return_final_state=True, dt_limit=(0.0, 5.0))
    torch.testing.assert_close(y, y_ref)
    assert f.dtype == torch.float32
    torch.testing.assert_close(f, f_ref.float())


def test_kernel_refuses_cpu_tensors():
    inp = make_inputs(1, 4, 2, 2, 1, 2)
    with pytest.raises(RuntimeError, match="CUDA"):
        ssd(**inp, impl="kernel")


def test_kernel_on_gpu_matches_recurrence():
    if not torch.cuda.is_available():
        pytest.skip("no CUDA device: the mamba-ssm Triton kernel runs on CUDA only")
    if not kernel_mod.mamba_ssm_installed():
        pytest.skip("mamba-ssm is not installed (pip install mamba-ssm --no-build-isolation)")
    inp = {k: v.float().cuda() for k, v in make_inputs(2, 200, 8, 64, 1, 64, seed=4).items()}
    y, f = ssd(**inp, return_final_state=True, impl="kernel", chunk_size=64)
    y_ref, f_ref = ssd_recurrence(**{k: v.double() for k, v in inp.items()}, return_final_state=True)
    tol = kernel_mod.KERNEL_TF32_ERROR  # the kernel's products are TF32
    assert (y.double() - y_ref).abs().max() <= tol * y_ref.abs().max()
    assert (f.double() - f_ref).abs().max() <= tol * f_ref.abs().max()


def test_tiled_recompute_path_matches(monkeypatch):
    """Inputs larger than TILE_ELEMENTS run in several tiles (the last one partial) in both passes."""
    import importlib

    intra = importlib.import_module("skeleton_mamba.ssd.intra_chunk")
    inp = make_inputs(3, 21, 4, 3, 2, 4, seed=9, d_shape="hp")
    ref = grads(ssd_recurrence, inp)
    y_ref = ssd_recurrence(**inp)
    monkeypatch.setattr(intra, "TILE_ELEMENTS", 4 * 8 * 8 * 2)  # two chunks of 8 per tile
    assert len(intra._tiles(3 * 3, 4 * 8 * 8)) == 5
    torch.testing.assert_close(ssd_chunked(**inp, chunk_size=8), y_ref, rtol=1e-10, atol=1e-10)
    got = grads(ssd_chunked, inp, chunk_size=8)
    for k in GRAD_NAMES:
        torch.testing.assert_close(got[k], ref[k], rtol=1e-9, atol=1e-9, msg=lambda m, k=k: f"grad {k}: {m}")


@pytest.mark.parametrize("L,block", [(1, 4), (7, 3), (16, 4), (23, 5), (40, 16), (41, 40)])
def test_quadratic_blocks_equal_recurrence_fp64(L, block):
    """Several blocks (the below-diagonal factorised part), lengths not multiples of the block."""
    inp = make_inputs(2, L, 4, 3, 2, 5, seed=L + block, d_shape="hp")
    inp["initial_state"] = None
    ref = ssd_recurrence(**inp)
    torch.testing.assert_close(ssd_quadratic(**inp, block_size=block), ref, rtol=1e-10, atol=1e-10)
    leaves = [
        {k: v.clone().requires_grad_(True) if v is not None else None for k, v in inp.items()}
        for _ in range(2)
    ]
    w = torch.randn(ref.shape, generator=torch.Generator().manual_seed(3), dtype=F64)
    (ssd_recurrence(**leaves[0]) * w).sum().backward()
    (ssd_quadratic(**leaves[1], block_size=block) * w).sum().backward()
    for k in ("x", "dt", "A", "B", "C", "D", "dt_bias"):
        torch.testing.assert_close(
            leaves[1][k].grad, leaves[0][k].grad, rtol=1e-9, atol=1e-9, msg=lambda m, k=k: f"grad {k}: {m}"
        )


def test_below_diagonal_blocks_loop_built_and_gradcheck():
    """The factorised blocks below the diagonal, two B/C groups of two heads, against entries built one by
    one (y_i = Σ_{j < s_I} exp(cs_i - cs_j) C_i·B_j Δ_j x_j) and their hand-written backward against finite
    differences (gradcheck)."""
    g = torch.Generator().manual_seed(5)
    b, q, K, H, P, G, N = 2, 3, 3, 4, 2, 2, 3
    L = q * K
    x, B, C = (torch.randn(*s, generator=g, dtype=F64) for s in ((b, L, H, P), (b, L, G, N), (b, L, G, N)))
    delta = torch.rand(b, L, H, generator=g, dtype=F64) + 0.1
    cs = (-delta * torch.rand(H, generator=g, dtype=F64) * 3).cumsum(1)
    want = torch.zeros(b, L, H, P, dtype=F64)
    for bi, i, h in itertools.product(range(b), range(q, L), range(H)):
        gi = h // (H // G)
        for j in range(i // q * q):
            w = math.exp(cs[bi, i, h] - cs[bi, j, h]) * float(C[bi, i, gi] @ B[bi, j, gi]) * delta[bi, j, h]
            want[bi, i, h] += w * x[bi, j, h]
    torch.testing.assert_close(below_diagonal(x, delta, cs, B, C, q), want, rtol=1e-12, atol=1e-12)
    leaves = [t.clone().requires_grad_(True) for t in (x, delta, cs, B, C)]
    assert torch.autograd.gradcheck(lambda *t: below_diagonal(*t, q), leaves)


def test_auto_dispatch_uses_blocks(monkeypatch):
    quad = importlib.import_module("skeleton_mamba.ssd.quadratic")
    monkeypatch.setattr(quad, "BLOCK_SIZE", 8)
    inp = make_inputs(1, 30, 2, 3, 1, 4, seed=4)
    inp["initial_state"] = None
    torch.testing.assert_close(ssd(**inp), ssd_recurrence(**inp), rtol=1e-10, atol=1e-10)
    with pytest.raises(ValueError, match="block_size"):
        ssd_quadratic(**inp, block_size=0)


def mamba2_init_inputs(b, L, H, P, N, seed):
    """fp32 inputs as an initialised Mamba-2 mixer sees them (as benchmarks/bench_ssd.py): A = -U(1, 16),
    Δ₀ log-uniform in [0.001, 0.1] through the inverse-softplus dt_bias, raw dt ~ N(0, 1)."""
    g = torch.Generator().manual_seed(seed)
    delta0 = torch.exp(torch.rand(H, generator=g) * (math.log(0.1) - math.log(1e-3)) + math.log(1e-3))
    delta0[0] = 0.1  # the fastest decay of the range: |cs| reaches ~10²
    A = -torch.empty(H).uniform_(1.0, 16.0, generator=g)
    A[0] = -16.0
    return dict(
        x=torch.randn(b, L, H, P, generator=g),
        dt=torch.randn(b, L, H, generator=g),
        A=A,
        B=torch.randn(b, L, 1, N, generator=g),
        C=torch.randn(b, L, 1, N, generator=g),
        D=torch.ones(H),
        dt_bias=delta0 + torch.log(-torch.expm1(-delta0)),
    )


@pytest.mark.parametrize("L", [150, 300])
def test_fp32_accuracy_at_fast_decay(L):
    """fp32 within 1e-5 absolute of the float64 recurrence where |cs| is in the hundreds (the regime of
    the issue: an fp32 cumsum of the log decays alone was off by 1e-5..3e-5 there)."""
    inp = mamba2_init_inputs(2, L, 4, 32, 32, seed=L)
    y_ref = ssd_recurrence(**{k: v.double() for k, v in inp.items()})
    delta = torch.nn.functional.softplus(inp["dt"] + inp["dt_bias"]).double()
    assert (delta * inp["A"].double()).sum(1).min() < -200  # the hard regime is really exercised
    for y in (
        ssd_quadratic(**inp),
        ssd_quadratic(**inp, block_size=L),
        ssd_chunked(**inp, chunk_size=64),
        ssd(**inp),
    ):
        assert y.dtype == torch.float32
        assert (y.double() - y_ref).abs().max() <= 1e-5


def test_split_cumsum_gives_float64_mask():
    """exp(hi_i - hi_j)·r_i·c_j (fp32 work only) equals the float64 mask to a few fp32 ulps, where the
    fp32 rounding of cs alone is off by u·|cs| (1e-5 and more at |cs| in the hundreds)."""
    intra = importlib.import_module("skeleton_mamba.ssd.intra_chunk")
    a = -torch.rand(3, 120, dtype=F64) * 4  # |cs| up to ~480
    cs = a.cumsum(-1)
    exact = segsum(a).exp()
    hi, r, c = intra.split_cumsum(cs, torch.float32)
    assert hi.dtype == r.dtype == c.dtype == torch.float32
    mask = decay_mask(hi).double() * r.double()[..., :, None] * c.double()[..., None, :]
    # entries are ≤ 1: the absolute error is the one that reaches y; the relative error grows as
    # u·|cs_i - cs_j| (exp of a correctly rounded difference), which is what bounds it here
    assert (mask - exact).abs().max() < 4e-7
    log_gap = segsum(a).clamp_min(-80.0).abs() + 2.0
    ok = exact > 1e-30
    assert ((mask - exact).abs() / exact)[ok].le(2 * 2.0**-24 * log_gap[ok]).all()
    assert (decay_mask(hi).double() - exact).abs().max() > 5e-6  # rounding cs to fp32 alone is not enough
    assert intra.split_cumsum(cs, F64)[1] is None  # nothing is rounded in float64


@pytest.mark.parametrize("use", ["both", "entering", "final"])
def test_state_passing_scan_and_its_backward(use):
    """Step 2 of the chunked form (a scan over chunks) equals the explicit recurrence
    S_{k+1} = d_k S_k + s_k, and its hand-written backward equals autograd through that recurrence."""
    from skeleton_mamba.ssd.state_scan import scan_states, scan_states_backward

    g = torch.Generator().manual_seed(0)
    b, c, H, N, P = 2, 5, 3, 4, 2
    s = torch.randn(b, c, H, N, P, dtype=F64, generator=g, requires_grad=True)
    d = torch.rand(b, c, H, dtype=F64, generator=g).requires_grad_(True)
    h0 = torch.randn(b, H, N, P, dtype=F64, generator=g, requires_grad=True)
    expected, state = [], h0
    for k in range(c):
        expected.append(state)
        state = d[:, k, :, None, None] * state + s[:, k]
    expected = torch.stack(expected, 1)
    S_in, final = scan_states(s.detach(), d.detach(), h0.detach())
    torch.testing.assert_close(S_in, expected, rtol=0, atol=1e-14)
    torch.testing.assert_close(final, state, rtol=0, atol=1e-14)

    dS_in = torch.randn(b, c, H, N, P, dtype=F64, generator=g) if use != "final" else torch.zeros_like(S_in)
    dfinal = torch.randn(b, H, N, P, dtype=F64, generator=g) if use != "entering" else None
    loss = (expected * dS_in).sum() + (0 if dfinal is None else (state * dfinal).sum())
    ref_s, ref_d, ref_h0 = torch.autograd.grad(loss, (s, d, h0))
    ds, dh0 = scan_states_backward(dS_in, d.detach(), dfinal)
    torch.testing.assert_close(ds, ref_s, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(dh0, ref_h0, rtol=1e-12, atol=1e-12)
    # the gradient of d_k, Σ G_{k+1} ⊙ S_k, which ChunkScan folds into that of the chunk total
    dd = torch.linalg.vecdot(ds.flatten(3), S_in.flatten(3))
    torch.testing.assert_close(dd, ref_d, rtol=1e-12, atol=1e-12)
