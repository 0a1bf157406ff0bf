"""Causal SkeletonMamba: frame-by-frame ``step`` equals the batch forward, in constant memory."""

import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.runtime import streaming
from skeleton_mamba.skeletons import SKELETONS

TINY_MIXER = MixerConfig(d_state=8, headdim=8, chunk_size=16)


def _causal_model(skeleton: str, context_dim=None, mixer=TINY_MIXER, seed=0) -> SkeletonMamba:
    torch.manual_seed(seed)
    cfg = SkeletonMambaConfig(
        skeleton=skeleton,
        in_channels=3,
        out_channels=5,
        dim=16,
        depth=2,
        mlp_dim=32,
        context_dim=context_dim,
        mixer=mixer,
        causal=True,
    )
    model = SkeletonMamba(cfg).double().eval()
    # Random A, dt and D (the initialisation makes D = 1 and A alike across heads).
    for p in model.parameters():
        p.data.add_(0.1 * torch.randn_like(p))
    return model


def _stream(model, x, context=None, **kwargs):
    state = model.init_state(x.shape[0])
    if kwargs:
        ys = [streaming.step(model, x[:, t], state, context, **kwargs)[0] for t in range(x.shape[1])]
    else:
        ys = [model.step(x[:, t], state, context)[0] for t in range(x.shape[1])]
    return torch.stack(ys, dim=1), state


@pytest.mark.parametrize("name", sorted(SKELETONS))
@pytest.mark.parametrize("with_context", [False, True])
def test_step_equals_causal_forward_for_every_skeleton(name, with_context):
    j = SKELETONS[name].num_joints
    model = _causal_model(name, context_dim=6 if with_context else None)
    torch.manual_seed(1)
    x = torch.randn(2, 37, j, 3, dtype=torch.float64)  # longer than two SSD chunks of 16
    context = torch.randn(2, 3, 6, dtype=torch.float64) if with_context else None
    with torch.no_grad():
        full = model(x, context=context)
    streamed, state = _stream(model, x, context)
    assert state.frames == 37
    torch.testing.assert_close(streamed, full, rtol=0, atol=1e-10)
    if name == "smpl24":  # the frame-wise scans through the modules' sequence path (bench_stream's reference)
        torch.testing.assert_close(_stream(model, x, context, ops=None)[0], full, rtol=0, atol=1e-10)


def test_causal_forward_ignores_the_future_and_bidirectional_does_not():
    torch.manual_seed(0)
    x = torch.randn(1, 20, 25, 3, dtype=torch.float64)
    x2 = x.clone()
    x2[:, 12:] += torch.randn_like(x2[:, 12:])
    causal = _causal_model("ntu25")
    with torch.no_grad():
        y, y2 = causal(x), causal(x2)
    torch.testing.assert_close(y[:, :12], y2[:, :12], rtol=0, atol=1e-12)
    assert not torch.allclose(y[:, 12:], y2[:, 12:])
    bidir = (
        SkeletonMamba(
            SkeletonMambaConfig(
                skeleton="ntu25", in_channels=3, dim=16, depth=1, mlp_dim=32, mixer=TINY_MIXER
            )
        )
        .double()
        .eval()
    )
    with torch.no_grad():
        assert not torch.allclose(bidir(x)[:, :12], bidir(x2)[:, :12])
    # The causal Temporal Scan has one direction only.
    assert causal.blocks[0].temporal_scan.backward_mixer is None


def test_state_size_does_not_grow_with_the_frames_seen():
    model = _causal_model("smpl24")
    state = model.init_state(1)
    shapes = [tuple(t.shape) for t in (*state.conv, *state.ssm)]
    ptrs = [t.data_ptr() for t in (*state.conv, *state.ssm)]
    nbytes = state.nbytes
    x = torch.randn(1, 24, 3, dtype=torch.float64)
    for _ in range(3):
        model.step(x, state)
    after_few = [t.clone() for t in state.ssm]
    for _ in range(200):
        model.step(x, state)
    assert state.nbytes == nbytes and state.frames == 203
    assert [tuple(t.shape) for t in (*state.conv, *state.ssm)] == shapes
    assert [t.data_ptr() for t in (*state.conv, *state.ssm)] == ptrs  # updated in place
    assert any(not torch.equal(a, b) for a, b in zip(after_few, state.ssm))  # it does evolve
    # Layout of mamba_ssm's Mamba2.allocate_inference_cache, per block: (B*J, conv_dim, d_conv),
    # (B*J, nheads, headdim, d_state); here d_inner 32, conv_dim 32 + 2*8, 4 heads of 8.
    assert shapes[0] == (24, 48, 4) and shapes[len(model.blocks)] == (24, 4, 8, 8)
    state.reset()
    assert state.frames == 0 and all(not t.any() for t in (*state.conv, *state.ssm))


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"d_ssm": 16, "D_has_hdim": True},  # a gated MLP beside the SSM, D per channel
        {"norm_before_gate": True, "dt_limit": (0.01, 0.05), "conv_bias": False, "bias": True},
        {"rmsnorm": False},
    ],
    ids=["default", "d_ssm+D_has_hdim", "norm_before_gate+dt_limit+biases", "no_rmsnorm"],
)
@pytest.mark.parametrize("compiled_form", [False, True], ids=["eager", "compiled_form"])
def test_mixer_step_with_grouped_B_and_C_equals_the_sequence_mixer(options, compiled_form, monkeypatch):
    """``Mamba2Mixer.step`` from ``allocate_inference_cache``, also in the form it takes under torch.compile
    (the state updated element-wise, ``_state_update_pointwise``), run eagerly here."""
    torch.manual_seed(0)
    from skeleton_mamba import Mamba2Mixer

    mixer = Mamba2Mixer(16, MixerConfig(d_state=4, headdim=4, ngroups=2, chunk_size=8, **options)).double()
    for p in mixer.parameters():
        p.data.add_(0.1 * torch.randn_like(p))
    u = torch.randn(3, 21, 16, dtype=torch.float64)
    with torch.no_grad():
        full = mixer(u)
        conv, ssm = mixer.allocate_inference_cache(3)
        monkeypatch.setattr(torch.compiler, "is_compiling", lambda: compiled_form)
        steps = torch.stack([mixer.step(u[:, t], conv, ssm) for t in range(21)], dim=1)
    torch.testing.assert_close(steps, full, rtol=0, atol=1e-10)


def test_float32_step_matches_the_forward():
    model = _causal_model("humanml3d22").float()
    x = torch.randn(1, 30, 22, 3)
    with torch.no_grad():
        full = model(x)
    streamed, state = _stream(model, x)
    assert state.ssm[0].dtype == torch.float32
    torch.testing.assert_close(streamed, full, rtol=1e-4, atol=1e-4)


def test_bad_use_is_explained():
    bidir = SkeletonMamba(
        SkeletonMambaConfig(skeleton="ntu25", in_channels=3, dim=16, depth=1, mlp_dim=32, mixer=TINY_MIXER)
    )
    with pytest.raises(ValueError, match="causal"):
        bidir.init_state(1)
    model = _causal_model("ntu25")
    state = model.init_state(2)
    with pytest.raises(ValueError, match="one frame"):
        model.step(torch.randn(2, 10, 25, 3, dtype=torch.float64), state)
    with pytest.raises(ValueError, match="one frame"):
        model.step(torch.randn(1, 25, 3, dtype=torch.float64), state)
    cond = _causal_model("ntu25", context_dim=4)
    with pytest.raises(ValueError, match="context"):
        cond.step(torch.randn(1, 25, 3, dtype=torch.float64), cond.init_state(1))


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"d_ssm": 16, "D_has_hdim": True},
        {"norm_before_gate": True, "dt_limit": (0.01, 0.05)},
        {"rmsnorm": False},
    ],
    ids=["default", "d_ssm+D_has_hdim", "norm_before_gate+dt_limit", "no_rmsnorm"],
)
@pytest.mark.parametrize("length", [1, 6, 40])
@pytest.mark.parametrize("compiled_form", [False, True], ids=["eager", "compiled_form"])
def test_short_mix_equals_the_sequence_mix(options, length, compiled_form, monkeypatch):
    """The frame path's few-operation mixer equals ``Mamba2Mixer.mix`` (chunked / quadratic SSD), also in
    the form it takes under torch.compile (the cumulative sums as a reduction), run eagerly here."""
    from skeleton_mamba import Mamba2Mixer
    from skeleton_mamba.runtime.frame_ops import short_mix

    torch.manual_seed(0)
    mixer = Mamba2Mixer(16, MixerConfig(d_state=4, headdim=4, ngroups=2, chunk_size=8, **options)).double()
    for p in mixer.parameters():
        p.data.add_(0.1 * torch.randn_like(p))
    zxbcdt = torch.randn(3, length, mixer.in_proj.out_features, dtype=torch.float64)
    with torch.no_grad():
        expected = mixer.mix(zxbcdt)
        monkeypatch.setattr(torch.compiler, "is_compiling", lambda: compiled_form)
        torch.testing.assert_close(short_mix(mixer, zxbcdt), expected, rtol=0, atol=1e-10)


def test_frame_linear_equals_linear_for_large_float32_weights():
    from skeleton_mamba.runtime.frame_ops import ONEDNN_MIN_WEIGHT, linear

    torch.manual_seed(0)
    layer = torch.nn.Linear(768, 1024)
    assert layer.weight.numel() >= ONEDNN_MIN_WEIGHT  # the oneDNN path where available
    x = torch.randn(1, 5, 768)
    with torch.no_grad():
        expected = x.double() @ layer.weight.double().t() + layer.bias.double()
        torch.testing.assert_close(linear(layer, x).double(), expected, rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(linear(layer.double(), x.double()), expected, rtol=0, atol=1e-12)


def test_a_non_finite_frame_streams_as_the_forward():
    """A NaN in one joint of frame 5 makes frames 5.. NaN, in the stream as in the forward."""
    model = _causal_model("smpl24")
    torch.manual_seed(1)
    x = torch.randn(1, 8, 24, 3, dtype=torch.float64)
    x[0, 5, 7, 1] = float("nan")
    with torch.no_grad():
        full = model(x)
    streamed, _ = _stream(model, x)
    assert full[:, 5:].isnan().all() and not full[:, :5].isnan().any()
    torch.testing.assert_close(streamed, full, rtol=0, atol=1e-10, equal_nan=True)


def test_keep_freed_memory_stops_the_page_faults_of_a_repeated_allocation():
    """glibc: the blocks a frame frees are reused; with the adaptive defaults the top of the heap was
    trimmed after such a frame and the next one faulted its pages in again (about 1,000 faults here)."""
    import platform
    import subprocess
    import sys

    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        pytest.skip("glibc's mallopt only")
    code = (
        "import resource, torch\n"
        "from skeleton_mamba.runtime.allocator import keep_freed_memory\n"
        "assert keep_freed_memory()\n"
        "def frame():\n"
        "    a, b, c = (torch.empty(n << 20).fill_(1) for n in (2, 3, 1))\n"
        "for _ in range(3): frame()\n"
        "for _ in range(3):\n"
        "    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt\n"
        "    for _ in range(50): frame()\n"
        "    print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)\n"
    )
    child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    # The best of three rounds of 50 frames: the glibc defaults fault in every round (about 9,000 faults
    # here); the kernel's own memory reclaim can add a stray 1,024 to one round on a busy machine.
    assert min(int(line) for line in child.stdout.split()) < 50
