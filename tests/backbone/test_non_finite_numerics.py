"""Non-finite values in the numerics: the SSD confines them like its recurrence; padding is absent."""

from __future__ import annotations

import inspect

import pytest
import torch

from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.config import MixerConfig
from skeleton_mamba.cross_attention import CrossAttention
from skeleton_mamba.group_scan import GroupScan
from skeleton_mamba.joint_scan import JointScan
from skeleton_mamba.norm import RMSNormGated
from skeleton_mamba.skeletons import DEFAULT_GROUP_PATHS, get_skeleton
from skeleton_mamba.ssd import ssd, ssd_chunked, ssd_recurrence
from skeleton_mamba.ssd.non_finite import inputs_finite
from skeleton_mamba.temporal_scan import TemporalScan
from skeleton_mamba.tokenizer import HumanTokenizer, InverseHumanTokenizer

NAN, INF = float("nan"), float("inf")
TINY = MixerConfig(d_state=8, headdim=8, chunk_size=16)
POISONS = [NAN, INF, -INF, 1e30]


def _ssd_inputs(b=2, L=90, H=4, P=3, G=2, N=5, seed=0):
    g = torch.Generator().manual_seed(seed)
    d = dict(dtype=torch.float64)
    return dict(x=torch.randn(b, L, H, P, generator=g, **d), dt=torch.randn(b, L, H, generator=g, **d),
                A=-torch.rand(H, generator=g, **d) - 0.5, B=torch.randn(b, L, G, N, generator=g, **d),
                C=torch.randn(b, L, G, N, generator=g, **d), D=torch.randn(H, generator=g, **d),
                dt_bias=torch.randn(H, generator=g, **d))  # fmt: skip


def _poison(inp, where):
    """Put a NaN / Inf into one entry of each named input (a step in the middle of a chunk)."""
    inp = {k: v.clone() for k, v in inp.items()}
    inp["x"][0, 50, 1, 2] = NAN if "x" in where else inp["x"][0, 50, 1, 2]
    if "dt" in where:
        inp["dt"][1, 37, 0] = NAN
    if "B" in where:
        inp["B"][1, 61, 1, 4] = INF  # group 1 = heads 2, 3
    if "C" in where:
        inp["C"][0, 20, 0, 1] = -INF  # step 20 only, heads 0, 1
    return inp


def _assert_like_recurrence(y, ref):
    finite = torch.isfinite(ref)
    assert torch.equal(torch.isfinite(y), finite), "non-finite outputs differ from the recurrence's"
    torch.testing.assert_close(y[finite], ref[finite], rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("impl", ["chunked", "quadratic", "torch"])
@pytest.mark.parametrize("where", [("x",), ("dt",), ("B",), ("C",), ("x", "dt", "B", "C")])
def test_a_non_finite_input_reaches_only_the_steps_the_recurrence_reaches(impl, where):
    inp = _poison(_ssd_inputs(), where)
    ref = ssd_recurrence(**inp)
    assert not torch.isfinite(ref).all()
    _assert_like_recurrence(ssd(**inp, impl=impl, chunk_size=16), ref)


def test_final_and_initial_states_follow_the_recurrence():
    inp = _poison(_ssd_inputs(), ("x", "dt", "B", "C"))
    h0 = torch.randn(2, 4, 3, 5, dtype=torch.float64)
    ref, ref_state = ssd_recurrence(**inp, initial_state=h0, return_final_state=True)
    y, state = ssd(**inp, impl="chunked", chunk_size=16, initial_state=h0, return_final_state=True)
    _assert_like_recurrence(y, ref)
    _assert_like_recurrence(state, ref_state)


def test_dt_minus_infinity_is_a_zero_step_as_in_the_recurrence():
    inp = _ssd_inputs()
    inp["dt"][0, 30, 2] = -INF  # softplus(-inf) = 0: a finite step that adds nothing
    ref = ssd_recurrence(**inp)
    assert torch.isfinite(ref).all()
    _assert_like_recurrence(ssd(**inp, impl="chunked", chunk_size=16), ref)


def test_the_unconfined_chunked_form_spreads_nan_backwards():
    """The bug being fixed: without the wrapper a NaN at step 50 reaches steps before it."""
    inp = _poison(_ssd_inputs(), ("x",))
    raw = inspect.unwrap(ssd_chunked)(**inp, chunk_size=16)  # below every wrapper (precision, non-finite)
    assert not torch.isfinite(raw[0, :50]).all()
    assert torch.isfinite(ssd_chunked(**inp, chunk_size=16)[0, :50]).all()


def test_gradients_of_steps_before_a_nan_stay_finite():
    inp = _poison(_ssd_inputs(), ("x", "B"))
    leaves = {k: v.clone().requires_grad_(True) for k, v in inp.items()}
    ssd(**leaves, impl="chunked", chunk_size=16)[:, :37].sum().backward()
    for name in ("x", "B", "C", "dt"):
        assert torch.isfinite(leaves[name].grad).all(), name


def test_the_fast_path_check_sees_every_non_finite_input():
    inp = _ssd_inputs()
    args = [inp[k] for k in ("x", "dt", "B", "C")]
    assert inputs_finite(*args)
    assert inputs_finite(*(a.half() for a in args))  # sums accumulate in fp32: no fp16 overflow
    for i in range(4):
        for poison in (NAN, INF, -INF):
            bad = [a.clone() for a in args]
            bad[i].view(-1)[7] = poison
            assert not inputs_finite(*bad)


# --- masked padding is absent, module by module and for the whole stack -----------------------------


def _frames_with_padding(poison, b=2, t=12, j=24, d=16, length=7, seed=0):
    """(x, x with ``poison`` in the padded frames of sequence 1, mask)."""
    x = torch.randn(b, t, j, d, generator=torch.Generator().manual_seed(seed))
    mask = torch.arange(t)[None] < torch.tensor([t, length])[:, None]
    dirty = x.clone()
    dirty[~mask] = poison
    return x, dirty, mask


@pytest.mark.parametrize("poison", POISONS)
def test_frame_wise_modules_keep_padding_in_its_frames(poison):
    torch.manual_seed(0)
    groups = get_skeleton("smpl24").groups
    tok, inv = HumanTokenizer(groups), InverseHumanTokenizer(groups, 24)
    group_scan, joint_scan = GroupScan(96, DEFAULT_GROUP_PATHS, mixer=TINY), JointScan(16, 6, mixer=TINY)
    gated_norm = RMSNormGated(16, group_size=8)
    modules = [
        lambda x: inv(joint_scan(group_scan(tok(x)))),
        lambda x: inv(tok(x).unflatten(-1, (6, 16))),
        torch.nn.LayerNorm(16),
        lambda x: gated_norm(x, x.flip(-1)),
    ]
    x, dirty, mask = _frames_with_padding(poison)
    with torch.no_grad():
        for module in modules:
            torch.testing.assert_close(module(dirty)[mask], module(x)[mask])


@pytest.mark.parametrize("poison", POISONS)
def test_temporal_scan_ignores_whatever_the_padding_holds(poison):
    torch.manual_seed(0)
    ts = TemporalScan(16, mixer=TINY)
    x, dirty, mask = _frames_with_padding(poison, t=40, j=3, length=23)
    with torch.no_grad():
        out = ts(dirty, mask)
        torch.testing.assert_close(out[mask], ts(x, mask)[mask])
        torch.testing.assert_close(out[1, :23], ts(x[1:, :23])[0], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("poison", POISONS)
def test_cross_attention_ignores_whatever_the_padded_condition_holds(poison):
    torch.manual_seed(0)
    attn = CrossAttention(16, 8, heads=2).eval()
    x, ctx = torch.randn(2, 5, 3, 16), torch.randn(2, 6, 8)
    cmask = torch.tensor([[True] * 6, [True] * 4 + [False] * 2])
    dirty = ctx.clone()
    dirty[~cmask] = poison
    with torch.no_grad():
        torch.testing.assert_close(attn(x, dirty, cmask), attn(x, ctx, cmask))


# 20 frames: the quadratic SSD form; 300 (> 256): the chunked form
@pytest.mark.parametrize(("frames", "poison"), [(20, p) for p in POISONS] + [(300, NAN), (300, 1e30)])
def test_the_backbone_ignores_whatever_the_padding_holds(frames, poison):
    torch.manual_seed(0)
    cfg = SkeletonMambaConfig(skeleton="ntu25", in_channels=3, dim=16, depth=2, mlp_dim=16, context_dim=8,
                              mixer=TINY)  # fmt: skip
    model = SkeletonMamba(cfg).eval()
    length = frames // 2 + 1
    x = torch.randn(2, frames, 25, 3)
    mask = torch.arange(frames)[None] < torch.tensor([frames, length])[:, None]
    ctx, cmask = torch.randn(2, 4, 8), torch.tensor([[True] * 4, [True, True, False, False]])
    dirty_x, dirty_ctx = x.clone(), ctx.clone()
    dirty_x[~mask], dirty_ctx[~cmask] = poison, poison
    with torch.no_grad():
        clean = model(x, mask, context=ctx, context_mask=cmask)
        out = model(dirty_x, mask, context=dirty_ctx, context_mask=cmask)
    torch.testing.assert_close(out[mask], clean[mask])
    assert torch.isfinite(out).all()  # the padding was replaced, so even padded outputs are finite


def test_backbone_gradients_stay_finite_with_nan_padding():
    torch.manual_seed(0)
    cfg = SkeletonMambaConfig(skeleton="ntu25", in_channels=3, dim=16, depth=1, mlp_dim=16, mixer=TINY)
    model = SkeletonMamba(cfg)
    x = torch.randn(2, 20, 25, 3)
    mask = torch.arange(20)[None] < torch.tensor([20, 9])[:, None]
    x[~mask] = NAN
    model(x, mask)[mask].square().mean().backward()
    assert all(torch.isfinite(p.grad).all() for p in model.parameters() if p.grad is not None)
