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
    """Time-step loop in float64 from the [Mamba-2] equations and ``mamba_ssm.Mamba2``'s option meanings.

    Conv window, dt = clamp(softplus(dt + dt_bias), dt_limit), recurrence h = exp(dt A) h + dt x B^T,
    y = h C + D x (D per head or per channel), gate (RMSNorm(y silu z), RMSNorm(y) silu z or y silu z),
    gated MLP silu(z0) x0 on the first d_inner - d_ssm channels, biases where configured.
    """
    cfg = mixer.config
    sd = {k: v.double() for k, v in mixer.state_dict().items()}
    u = u.double()
    b, length, _ = u.shape
    di = cfg.expand * mixer.d_model
    ds = di if cfg.d_ssm is None else cfg.d_ssm
    dm = di - ds
    n, g, p = cfg.d_state, cfg.ngroups, cfg.headdim
    h = ds // p
    lo, hi = cfg.dt_limit
    proj = u @ sd["in_proj.weight"].T + (sd["in_proj.bias"] if cfg.bias else 0.0)
    z0, x0 = proj[..., :dm], proj[..., dm : 2 * dm]
    z = proj[..., 2 * dm : 2 * dm + ds]
    xbc_raw = proj[..., 2 * dm + ds : 2 * dm + 2 * ds + 2 * g * n]
    dt_raw = proj[..., 2 * dm + 2 * ds + 2 * g * n :]
    assert dt_raw.shape[-1] == h
    w = sd["conv1d.weight"][:, 0]
    cb = sd["conv1d.bias"] if cfg.conv_bias else torch.zeros(w.shape[0], dtype=torch.float64)
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
            x, bb, cc = xbc[:ds].view(h, p), xbc[ds : ds + g * n].view(g, n), xbc[ds + g * n :].view(g, n)
            y = torch.zeros(h, p, dtype=torch.float64)
            for hd in range(h):
                gi = hd // (h // g)
                dt = min(max(F.softplus(dt_raw[bi, t, hd] + sd["dt_bias"][hd]).item(), lo), hi)
                a = -math.exp(sd["A_log"][hd].item())
                state[hd] = math.exp(dt * a) * state[hd] + dt * torch.outer(x[hd], bb[gi])
                skip = sd["D"][hd * p : (hd + 1) * p] if cfg.D_has_hdim else sd["D"][hd]
                y[hd] = state[hd] @ cc[gi] + skip * x[hd]
            y = y.reshape(-1)
            gate = F.silu(z[bi, t])
            if cfg.rmsnorm:
                pre = y if cfg.norm_before_gate else y * gate
                grouped = pre.view(g, -1)
                normed = (grouped / torch.sqrt(grouped.pow(2).mean(-1, keepdim=True) + 1e-5)).reshape(-1)
                normed = normed * sd["norm.weight"]
                y = normed * gate if cfg.norm_before_gate else normed
            else:
                y = y * gate
            y = torch.cat([F.silu(z0[bi, t]) * x0[bi, t], y])
            out[bi, t] = y @ sd["out_proj.weight"].T + (sd["out_proj.bias"] if cfg.bias else 0.0)
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


OPTIONS = [
    dict(norm_before_gate=True),
    dict(dt_limit=(0.05, 0.3)),
    dict(D_has_hdim=True),
    dict(rmsnorm=False),
    dict(conv_bias=False, bias=True),
    dict(d_ssm=16),  # 16 SSM channels + 16 gated-MLP channels of d_inner 32
    dict(d_ssm=16, ngroups=2, norm_before_gate=True, D_has_hdim=True, dt_limit=(0.0, 0.2)),
]


@pytest.mark.parametrize("options", OPTIONS, ids=lambda o: ",".join(o))
def test_mixer_options_match_stepwise_reference(options):
    """Each mamba_ssm option changes the computation as the reference loop says, and differs from default."""
    cfg = MixerConfig(d_state=8, headdim=8, chunk_size=8, **options)
    torch.manual_seed(5)
    mixer = Mamba2Mixer(16, cfg).double()
    with torch.no_grad():
        mixer.A_log.uniform_(-1.0, 1.0)
        mixer.D.uniform_(-1.0, 1.0)
        mixer.dt_bias.uniform_(-3.0, 1.0)  # softplus spans 0.05 .. 1.3: dt_limit clamps both ends
        if cfg.rmsnorm:
            mixer.norm.weight.uniform_(0.5, 1.5)
        for lin in (mixer.in_proj, mixer.out_proj):
            if lin.bias is not None:
                lin.bias.uniform_(-1.0, 1.0)
    u = torch.randn(2, 13, 16, dtype=torch.float64)
    torch.testing.assert_close(mixer(u), _reference_mixer(mixer, u), rtol=1e-9, atol=1e-9)
    plain_cfg = MixerConfig(d_state=8, headdim=8, chunk_size=8)
    assert not torch.allclose(_reference_mixer(mixer, u), _reference_with_config(mixer, plain_cfg, u))


def _reference_with_config(mixer: Mamba2Mixer, cfg: MixerConfig, u: torch.Tensor) -> torch.Tensor:
    """The reference loop run with the same weights read under the default options (where shapes allow)."""
    other = Mamba2Mixer(mixer.d_model, cfg).double()
    state = {k: v for k, v in mixer.state_dict().items() if k in other.state_dict()}
    state = {k: v for k, v in state.items() if v.shape == other.state_dict()[k].shape}
    other.load_state_dict(state, strict=False)
    return _reference_mixer(other, u)


def test_mixer_option_state_dict_keys_and_shapes_follow_mamba_ssm():
    cfg = MixerConfig(
        d_state=8, headdim=8, d_ssm=16, D_has_hdim=True, rmsnorm=False, bias=True, conv_bias=False
    )
    shapes = {k: tuple(v.shape) for k, v in Mamba2Mixer(16, cfg).state_dict().items()}
    # mamba_ssm: in_proj 2 d_inner + 2 G N + H, conv over d_ssm + 2 G N, D (d_ssm,), no norm, biases on.
    assert shapes == {
        "in_proj.weight": (2 * 32 + 2 * 8 + 2, 16),
        "in_proj.bias": (2 * 32 + 2 * 8 + 2,),
        "conv1d.weight": (16 + 2 * 8, 1, 4),
        "dt_bias": (2,),
        "A_log": (2,),
        "D": (16,),
        "out_proj.weight": (16, 32),
        "out_proj.bias": (16,),
    }


@pytest.mark.parametrize(
    "options,message",
    [
        (dict(dt_limit=(0.5, 0.1)), "dt_limit"),
        (dict(dt_limit=(-1.0, 1.0)), "dt_limit"),
        (dict(dt_limit=(0.1,)), "dt_limit"),
        (dict(d_ssm=12), "multiple of headdim"),
        (dict(d_ssm=64), "d_ssm"),
        (dict(rmsnorm=False, norm_before_gate=True), "rmsnorm"),
    ],
)
def test_mixer_rejects_impossible_options(options, message):
    with pytest.raises(ValueError, match=message):
        Mamba2Mixer(16, MixerConfig(d_state=8, headdim=8, **options))
