"""The SSD under bf16 autocast: its decays, cumulative sums, products and states stay fp32 ([Mamba-2]).

Two kinds of check. Dtypes: every matrix product, exponential and cumulative sum the SSD forms (and the
mixer's one-token step) run under ``torch.autocast("cpu", torch.bfloat16)`` is logged at the ATen level
(below autocast, so what actually ran) and must be fp32 or fp64; the state comes back fp32. Values: with
bf16 inputs, the autocast output is the fp32 output of the same inputs rounded once to bf16 (bit for
bit), and both are compared with the float64 sequential recurrence of those inputs as truth.
"""

from __future__ import annotations

import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode

from skeleton_mamba import MixerConfig
from skeleton_mamba.mixer import Mamba2Mixer
from skeleton_mamba.ssd import ssd, ssd_recurrence

BF16, F32, F64 = torch.bfloat16, torch.float32, torch.float64
# ATen ops that carry the SSD's decays, cumulative sums and states (matmul lowers to mm/bmm).
WATCHED = {"mm", "bmm", "baddbmm", "addmm", "addbmm", "matmul", "linalg_vecdot", "exp", "exp_", "cumsum"}
WATCHED |= {"cumsum_", "baddbmm_", "addcmul", "addcmul_"}
# Stated bound: the autocast SSD output against the float64 recurrence, elementwise,
# |y_bf16 - y_true| <= 2^-8 |y_true| + 2^-12 max|y_true| (one bf16 rounding of y, 2^-9 relative, with margin).
REL, ABS = 2.0**-8, 2.0**-12


class DtypeLog(TorchDispatchMode):
    """Records (op, floating dtypes of its tensor arguments) for the ATen ops in ``WATCHED``."""

    def __init__(self):
        super().__init__()
        self.calls: list[tuple[str, set[torch.dtype]]] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        name = func.overloadpacket.__name__
        if name in WATCHED:
            flat = list(args) + list((kwargs or {}).values())
            dtypes = {a.dtype for a in flat if isinstance(a, torch.Tensor) and a.is_floating_point()}
            self.calls.append((name, dtypes))
        return func(*args, **(kwargs or {}))

    def low_precision(self) -> list[tuple[str, set[torch.dtype]]]:
        return [c for c in self.calls if c[1] & {BF16, torch.float16}]


def bf16_inputs(b=2, L=150, H=4, P=8, G=2, N=8, seed=0):
    """SSD inputs as the mixer hands them over under autocast: x, dt, B, C in bf16 (outputs of bf16
    products), A, D, dt_bias fp32 parameters; initial state fp32."""
    g = torch.Generator().manual_seed(seed)
    r = lambda *s: torch.randn(*s, generator=g)  # noqa: E731
    return dict(
        x=r(b, L, H, P).to(BF16),
        dt=r(b, L, H).to(BF16),
        A=-(0.5 + 7.5 * torch.rand(H, generator=g)),
        B=r(b, L, G, N).to(BF16),
        C=r(b, L, G, N).to(BF16),
        D=r(H),
        dt_bias=r(H) - 1.0,
        initial_state=r(b, H, P, N),
    )


def as_dtype(inp: dict, dtype: torch.dtype) -> dict:
    return {k: v.to(dtype) for k, v in inp.items()}


def f64_params(inp: dict) -> dict:
    """D and dt_bias in float64, for the truth."""
    return dict(D=inp["D"].to(F64), dt_bias=inp["dt_bias"].to(F64))


def test_the_log_sees_bf16_products_under_autocast():
    """The check is sensitive: a plain product under autocast is logged as a bf16 ``mm``."""
    with torch.autocast("cpu", dtype=BF16), DtypeLog() as log:
        torch.randn(4, 4) @ torch.randn(4, 4)
    assert log.low_precision(), log.calls


@pytest.mark.parametrize("impl", ["recurrence", "chunked", "quadratic"])
@pytest.mark.parametrize("stateful", [False, True])
def test_decays_cumsums_products_and_states_stay_fp32_under_autocast(impl, stateful):
    """Forward under autocast, backward after it (as Lightning's mixed precision and the PyTorch docs do)."""
    inp = bf16_inputs()
    leaves = {k: v.requires_grad_() for k, v in inp.items() if k in ("x", "dt", "B", "C", "A", "D")}
    kwargs = dict(D=inp["D"], dt_bias=inp["dt_bias"], chunk_size=32, impl=impl)
    if stateful:
        kwargs.update(initial_state=inp["initial_state"], return_final_state=True)
    with DtypeLog() as log:
        with torch.autocast("cpu", dtype=BF16):
            out = ssd(inp["x"], inp["dt"], inp["A"], inp["B"], inp["C"], **kwargs)
            y, final = out if stateful else (out, None)
            loss = y.float().square().sum() + (final.square().sum() if stateful else 0.0)
        loss.backward()
    assert log.calls and not log.low_precision(), log.low_precision()[:5]
    assert y.dtype == BF16
    if stateful:
        assert final.dtype == F32
    assert all(torch.isfinite(t.grad).all() for t in leaves.values())


@pytest.mark.parametrize("length", [40, 150])  # one chunk (IntraChunk), several (ChunkScan)
def test_hand_written_backwards_stay_fp32_when_backward_runs_inside_autocast(length):
    """The chunked form's own backwards switch autocast off themselves (autograd's formulas would not)."""
    inp = bf16_inputs(L=length)
    leaves = [inp[k].requires_grad_() for k in ("x", "dt", "B", "C", "A", "D")]
    with torch.autocast("cpu", dtype=BF16), DtypeLog() as log:
        y = ssd(inp["x"], inp["dt"], inp["A"], inp["B"], inp["C"], D=inp["D"], dt_bias=inp["dt_bias"],
                chunk_size=64, impl="chunked")  # fmt: skip
        y.float().square().sum().backward()
    assert log.calls and not log.low_precision(), log.low_precision()[:5]
    assert all(torch.isfinite(t.grad).all() for t in leaves)


@pytest.mark.parametrize("impl", ["recurrence", "chunked", "quadratic"])
def test_autocast_output_is_the_fp32_output_rounded_once_and_near_the_float64_recurrence(impl):
    inp = bf16_inputs(seed=1)
    args = ("x", "dt", "A", "B", "C")
    kwargs = dict(chunk_size=32, impl=impl, initial_state=None)

    def run(d, **kw):
        return ssd(*(d[k] for k in args), D=d["D"], dt_bias=d["dt_bias"], **{**kwargs, **kw})

    truth = ssd_recurrence(*(inp[k].to(F64) for k in args), **f64_params(inp))
    y32 = run(as_dtype(inp, F32))
    with torch.autocast("cpu", dtype=BF16):
        y16 = run(inp)
    assert torch.equal(y16, y32.to(BF16))  # the SSD ran in fp32; only y was rounded
    scale = truth.abs().max()
    err16, err32 = (y16.to(F64) - truth).abs(), (y32.to(F64) - truth).abs()
    assert (err16 <= REL * truth.abs() + ABS * scale).all(), (err16 / (truth.abs() + scale * 1e-3)).max()
    assert err32.max() <= 1e-5 * scale, err32.max() / scale


def test_autocast_final_state_equals_the_fp32_one():
    inp = bf16_inputs(seed=2)
    args = ("x", "dt", "A", "B", "C")

    def run(d):
        return ssd(*(d[k] for k in args), D=d["D"], dt_bias=d["dt_bias"], chunk_size=32,
                   initial_state=d["initial_state"], return_final_state=True)  # fmt: skip

    y32, s32 = run(as_dtype(inp, F32))
    with torch.autocast("cpu", dtype=BF16):
        y16, s16 = run(inp)
    h0 = inp["initial_state"].to(F64)
    truth = ssd_recurrence(*(inp[k].to(F64) for k in args), **f64_params(inp), initial_state=h0,
                           return_final_state=True)[1]  # fmt: skip
    assert s16.dtype == F32 and torch.equal(s16, s32)
    assert (s16.to(F64) - truth).abs().max() <= 1e-5 * truth.abs().max()


def test_mixer_step_keeps_its_state_and_state_products_in_fp32_under_autocast():
    torch.manual_seed(0)
    mixer = Mamba2Mixer(32, MixerConfig(d_state=8, headdim=8, chunk_size=16)).eval()
    u = torch.randn(3, 12, 32)
    conv, state = mixer.allocate_inference_cache(3)
    conv32, state32 = mixer.allocate_inference_cache(3)
    with torch.no_grad():
        for t in range(u.shape[1]):
            with torch.autocast("cpu", dtype=BF16), DtypeLog() as log:
                mixer.step(u[:, t], conv, state)
            mixer.step(u[:, t], conv32, state32)
            state_ops = [c for c in log.calls if c[0] in ("bmm", "baddbmm", "baddbmm_")]
            assert state_ops and all(c[1] <= {F32} for c in state_ops), state_ops
    assert state.dtype == F32
    # only the projections ran in bf16: the state after 12 steps stays within 2 % of the fp32 one
    assert (state - state32).abs().max() <= 0.02 * state32.abs().max()
