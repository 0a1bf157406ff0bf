"""The compiled frame step (skeleton_mamba.runtime.compiling) equals the eager step and the causal forward."""

import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.runtime.compiling import CompiledStep, compile_step_or_eager, inductor_unavailable

needs_inductor = pytest.mark.skipif(inductor_unavailable() is not None, reason=str(inductor_unavailable()))


def _tiny_model(context_dim=None) -> SkeletonMamba:
    """One block at tiny widths (a short compile: 10 to 40 s), random weights (fp32, the streaming dtype)."""
    torch.manual_seed(0)
    cfg = SkeletonMambaConfig(
        skeleton="smpl24", in_channels=3, out_channels=5, dim=16, depth=1, mlp_dim=32,
        mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16), causal=True, context_dim=context_dim,
    )  # fmt: skip
    model = SkeletonMamba(cfg).eval()
    with torch.no_grad():
        for p in model.parameters():  # A, dt and D unlike across heads
            p.add_(0.1 * torch.randn_like(p))
    return model


@pytest.fixture(scope="module")
def compiled():
    """A tiny model with a cross-attention context, its compiled step (compiled once here, batch 2) and
    a context (2, 3, 6) for every frame."""
    model = _tiny_model(context_dim=6)
    context = torch.randn(2, 3, 6, generator=torch.Generator().manual_seed(2))
    step = model.compile_step()
    step(torch.zeros(2, 24, 3), model.init_state(2), context)  # compiles
    return model, step, context


@needs_inductor
def test_compiled_step_equals_the_eager_step_and_the_forward(compiled):
    model, step, context = compiled
    torch.manual_seed(1)
    x = torch.randn(2, 6, 24, 3)
    with torch.no_grad():
        full = model(x, context=context)  # the batch forward (the sequence path), independent of both steps
    state, eager_state = model.init_state(2), model.init_state(2)
    tensors = [*state.conv, *state.ssm]
    pointers = [t.data_ptr() for t in tensors]
    ys = []
    for t in range(6):
        y, returned = step(x[:, t], state, context)
        y_eager, _ = model.step(x[:, t], eager_state, context)
        assert returned is state
        # fp32 rounding of a different operator order (fused loops, prepacked weights)
        torch.testing.assert_close(y, y_eager, rtol=1e-5, atol=1e-5)
        for a, b in zip((*state.conv, *state.ssm), (*eager_state.conv, *eager_state.ssm)):
            torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)  # the state written back in place
        ys.append(y)
    torch.testing.assert_close(torch.stack(ys, dim=1), full, rtol=1e-5, atol=1e-5)
    assert state.frames == 6 and state.ssm[0].abs().sum() > 0
    assert [t.data_ptr() for t in (*state.conv, *state.ssm)] == pointers  # same tensors, same layout
    assert [t.shape for t in (*state.conv, *state.ssm)] == [t.shape for t in tensors]
    assert len(step.signatures) == 1


@needs_inductor
def test_a_new_batch_size_past_the_recompile_limit_raises_instead_of_running_eagerly(compiled):
    model, step, context = compiled
    limit = torch._dynamo.config.recompile_limit
    torch._dynamo.config.recompile_limit = 1  # the batch-2 version fills it
    try:
        with pytest.raises(RuntimeError, match="recompile_limit"):
            step(torch.zeros(1, 24, 3), model.init_state(1), context[:1])
    finally:
        torch._dynamo.config.recompile_limit = limit
    # The step's own checks come first.
    with pytest.raises(ValueError, match="one frame"):
        step(torch.zeros(3, 24, 3), model.init_state(2), context)
    with pytest.raises(ValueError, match="pass a context"):
        step(torch.zeros(2, 24, 3), model.init_state(2))


def test_a_weight_change_after_compiling_is_refused():
    model = _tiny_model()
    step = CompiledStep(model)  # checked before the compiled call: nothing is compiled here
    with torch.no_grad():
        model.output_proj.bias.add_(1.0)
    with pytest.raises(RuntimeError, match="weights changed"):
        step(torch.zeros(1, 24, 3), model.init_state(1))


def test_a_failing_compile_falls_back_to_the_eager_step(monkeypatch):
    model = _tiny_model()

    def no_compiler(self, *args, **kwargs):
        raise RuntimeError("InductorError: CppCompileError: C++ compile error\nno compiler found")

    monkeypatch.setattr(CompiledStep, "__call__", no_compiler)
    with pytest.warns(RuntimeWarning, match="compiling the frame step failed .*CppCompileError.*eagerly"):
        step, seconds = compile_step_or_eager(model, batch=2)
    assert seconds is None and step == model.step
    y, state = step(torch.zeros(2, 24, 3), model.init_state(2))
    assert y.shape == (2, 24, 5) and state.frames == 1


@needs_inductor
def test_the_frame_linear_compiles_for_large_float32_weights():
    """Eagerly, large fp32 weights go through oneDNN's eager op (which inductor cannot lower); compiled,
    ``frame_ops.linear`` is ``F.linear`` and inductor packs the frozen weight for oneDNN itself."""
    from skeleton_mamba.runtime.compiling import compile_for_inference
    from skeleton_mamba.runtime.frame_ops import ONEDNN_MIN_WEIGHT, linear

    torch.manual_seed(0)
    layer = torch.nn.Linear(768, 1024).eval()
    assert layer.weight.numel() >= ONEDNN_MIN_WEIGHT
    x = torch.randn(1, 5, 768)
    compiled = compile_for_inference(lambda x: linear(layer, x))
    with torch.inference_mode():
        y = compiled(x)
    expected = x.double() @ layer.weight.double().t() + layer.bias.double()
    torch.testing.assert_close(y.double(), expected, rtol=1e-5, atol=1e-5)


@needs_inductor
def test_compile_for_inference_freezes_the_weights():
    """Frozen means the weights are constants of the compiled graph (what lets inductor prepack them):
    changing a parameter in place afterwards does not change the compiled function's output."""
    from skeleton_mamba.runtime.compiling import compile_for_inference

    torch.manual_seed(0)
    layer = torch.nn.Linear(64, 32).eval()
    x = torch.randn(3, 64)
    frozen = compile_for_inference(lambda x: layer(x))
    live = compile_for_inference(lambda x: layer(x) + 0.0, freezing=False)
    with torch.inference_mode():
        before, live_before = frozen(x), live(x)
    with torch.no_grad():
        layer.weight.add_(1.0)
    with torch.inference_mode():
        after, live_after = frozen(x), live(x)
        eager = layer(x)
    torch.testing.assert_close(after, before)
    torch.testing.assert_close(live_after, eager)
    assert (live_after - live_before).abs().max() > 1.0
