"""The Mamba-2 mixer against a step-by-step float64 computation written independently of it."""

import math

import pytest
import torch
import torch.nn.functional as F

from skeleton_mamba.causal_conv import causal_depthwise_conv
from skeleton_mamba.config import MixerConfig
from skeleton_mamba.mixer import Mamba2Mixer
from skeleton_mamba.norm import RMSNormGated

# The state_dict of mamba_ssm.modules.mamba2.Mamba2 (rmsnorm=True, bias=False, conv_bias=True).
MAMBA2_KEYS = {
    "in_proj.weight",
    "conv1d.weight",
    "conv1d.bias",
    "dt_bias",
    "A_log",
    "D",
    "norm.weight",
    "out_proj.weight",
}


def test_parameter_names_and_shapes_match_mamba_ssm():
    mixer = Mamba2Mixer(128)  # width 128, expand 2, headdim 64, d_state 64 -> 4 heads
    shapes = {k: tuple(v.shape) for k, v in mixer.state_dict().items()}
    assert set(shapes) == MAMBA2_KEYS
    assert shapes["in_proj.weight"] == (2 * 256 + 2 * 64 + 4, 128)  # 644 = [z, x, B, C, dt]
    assert shapes["conv1d.weight"] == (256 + 2 * 64, 1, 4)
    assert shapes["dt_bias"] == shapes["A_log"] == shapes["D"] == (4,)
    assert shapes["norm.weight"] == (256,) and shapes["out_proj.weight"] == (128, 256)


def test_official_initialisation_ranges():
    torch.manual_seed(0)
    cfg = MixerConfig(headdim=8)
    mixer = Mamba2Mixer(256, cfg)  # 64 heads
    dt = F.softplus(mixer.dt_bias)
    assert dt.min() >= cfg.dt_init_floor * 0.999 and dt.max() <= cfg.dt_max * 1.001
    assert dt.min() >= cfg.dt_min * 0.999
    a = torch.exp(mixer.A_log)
    assert a.min() >= 1.0 and a.max() <= 16.0
    assert torch.equal(mixer.D, torch.ones(64))
    assert all(getattr(p, "_no_weight_decay", False) for p in (mixer.dt_bias, mixer.A_log, mixer.D))


def _reference_mixer(mixer: Mamba2Mixer, u: torch.Tensor) -> torch.Tensor:
    """Time-step loop in float64: conv window, recurrence h = exp(dt A) h + dt x B^T, gated RMSNorm."""
    sd = {k: v.double() for k, v in mixer.state_dict().items()}
    u = u.double()
    b, length, _ = u.shape
    di, n, h, g = mixer.d_inner, mixer.d_state, mixer.nheads, mixer.ngroups
    p = mixer.headdim
    proj = u @ sd["in_proj.weight"].T
    z, xbc_raw, dt_raw = proj[..., :di], proj[..., di : 2 * di + 2 * g * n], proj[..., 2 * di + 2 * g * n :]
    w, cb = sd["conv1d.weight"][:, 0], sd["conv1d.bias"]
    k = w.shape[1]
    out = torch.zeros(b, length, mixer.d_model, dtype=torch.float64)
    for bi in range(b):
        state = torch.zeros(h, p, n, dtype=torch.float64)
        for t in range(length):
            window = torch.zeros(xbc_raw.shape[-1], dtype=torch.float64)
            for s in range(k):  # causal conv: output t sees inputs t-k+1 .. t
                src = t - (k - 1) + s
                if src >= 0:
                    window += w[:, s] * xbc_raw[bi, src]
            xbc = F.silu(window + cb)
            x, bb, cc = xbc[:di].view(h, p), xbc[di : di + g * n].view(g, n), xbc[di + g * n :].view(g, n)
            y = torch.zeros(h, p, dtype=torch.float64)
            for hi in range(h):
                gi = hi // (h // g)
                dt = F.softplus(dt_raw[bi, t, hi] + sd["dt_bias"][hi])
                a = -math.exp(sd["A_log"][hi].item())
                state[hi] = math.exp(dt.item() * a) * state[hi] + dt * torch.outer(x[hi], bb[gi])
                y[hi] = state[hi] @ cc[gi] + sd["D"][hi] * x[hi]
            yz = y.reshape(-1) * F.silu(z[bi, t])
            yz = yz.view(g, -1)
            yz = yz / torch.sqrt(yz.pow(2).mean(-1, keepdim=True) + 1e-5)
            out[bi, t] = (yz.reshape(-1) * sd["norm.weight"]) @ sd["out_proj.weight"].T
    return out


@pytest.mark.parametrize("length,ngroups", [(7, 1), (19, 2)])
def test_mixer_matches_stepwise_reference(length, ngroups):
    torch.manual_seed(1)
    mixer = Mamba2Mixer(16, MixerConfig(d_state=8, headdim=8, ngroups=ngroups, chunk_size=8)).double()
    with torch.no_grad():  # make the dynamics non-trivial
        mixer.A_log.uniform_(-1.0, 1.0)
        mixer.D.uniform_(-1.0, 1.0)
        mixer.norm.weight.uniform_(0.5, 1.5)
    u = torch.randn(2, length, 16, dtype=torch.float64)
    torch.testing.assert_close(mixer(u), _reference_mixer(mixer, u), rtol=1e-9, atol=1e-9)


def test_mixer_is_causal():
    torch.manual_seed(2)
    mixer = Mamba2Mixer(32, MixerConfig(d_state=16, headdim=16, chunk_size=16))
    u = torch.randn(1, 40, 32)
    v = u.clone()
    v[:, 25:] = torch.randn(1, 15, 32)
    a, b = mixer(u), mixer(v)
    torch.testing.assert_close(a[:, :25], b[:, :25])
    assert not torch.allclose(a[:, 25:], b[:, 25:])


def test_gated_rmsnorm_per_group_against_hand_formula():
    torch.manual_seed(3)
    norm = RMSNormGated(8, group_size=4)
    with torch.no_grad():
        norm.weight.copy_(torch.arange(1.0, 9.0))
    y, z = torch.randn(3, 8), torch.randn(3, 8)
    gated = y * z * torch.sigmoid(z)
    expected = torch.cat(
        [
            gated[:, :4] / (gated[:, :4].pow(2).mean(-1, keepdim=True) + 1e-5).sqrt(),
            gated[:, 4:] / (gated[:, 4:].pow(2).mean(-1, keepdim=True) + 1e-5).sqrt(),
        ],
        dim=-1,
    ) * torch.arange(1.0, 9.0)
    torch.testing.assert_close(norm(y, z), expected)
    before = RMSNormGated(8, norm_before_gate=True)
    expected_before = y / (y.pow(2).mean(-1, keepdim=True) + 1e-5).sqrt() * F.silu(z)
    torch.testing.assert_close(before(y, z), expected_before)


@pytest.mark.parametrize("k,length", [(4, 1), (4, 9), (2, 5), (1, 3)])
def test_causal_conv_and_its_gradients_match_conv1d(k, length):
    """The CPU causal depthwise convolution against torch's conv1d (padding k - 1, first L outputs)."""
    torch.manual_seed(4)
    channels = 5
    x = torch.randn(3, length, channels, dtype=torch.float64, requires_grad=True)
    weight = torch.randn(channels, k, dtype=torch.float64, requires_grad=True)
    bias = torch.randn(channels, dtype=torch.float64, requires_grad=True)
    upstream = torch.randn(3, length, channels, dtype=torch.float64)
    ours = causal_depthwise_conv(x, weight, bias)
    reference = F.conv1d(x.transpose(1, 2), weight[:, None], bias, padding=k - 1, groups=channels)
    reference = reference[..., :length].transpose(1, 2)
    torch.testing.assert_close(ours, reference, rtol=1e-12, atol=1e-12)
    g_ours = torch.autograd.grad((ours * upstream).sum(), (x, weight, bias))
    g_ref = torch.autograd.grad((reference * upstream).sum(), (x, weight, bias))
    for a, b in zip(g_ours, g_ref):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)
    small = (x[:1, :, :2], weight[:2], bias[:2])
    assert torch.autograd.gradcheck(causal_depthwise_conv, [t.detach().requires_grad_() for t in small])
