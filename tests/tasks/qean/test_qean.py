"""QEAN: quaternion algebra, Spin Position Embedding, Quaternion Rotary Attention, model and generation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from scipy.linalg import polar
from scipy.spatial.transform import Rotation

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.motion.formats.fact_features import (
    features_to_joints,
    features_to_smpl,
    nearest_rotation,
    smpl_to_features,
)
from skeleton_mamba.tasks.qean.attention import (
    QuaternionRotaryAttention,
    quaternion_rotary_attention,
    series_rotation,
)
from skeleton_mamba.tasks.qean.generate import generate_fast, generate_plain
from skeleton_mamba.tasks.qean.model import QEAN, QEANConfig
from skeleton_mamba.tasks.qean.quaternion import (
    hamilton_product,
    quaternion_conjugate,
    quaternion_flatten,
    quaternion_parameterise,
)
from skeleton_mamba.tasks.qean.rotary import SpinPositionEmbedding, apply_rotary

ONE, I, J, K = (torch.eye(4, dtype=torch.float64)[n] for n in range(4))


def test_hamilton_product_unit_table():
    assert torch.equal(hamilton_product(I, J), K)
    assert torch.equal(hamilton_product(J, I), -K)
    assert torch.equal(hamilton_product(J, K), I)
    assert torch.equal(hamilton_product(K, J), -I)
    assert torch.equal(hamilton_product(K, I), J)
    assert torch.equal(hamilton_product(I, K), -J)
    for u in (I, J, K):
        assert torch.equal(hamilton_product(u, u), -ONE)
    assert torch.equal(hamilton_product(hamilton_product(I, J), K), -ONE)  # ijk = -1


def test_hamilton_product_hand_values_and_j_component():
    # (1 + 2i + 3j + 4k)(5 + 6i + 7j + 8k) = -60 + 12i + 30j + 24k (worked by hand)
    q = torch.tensor([1.0, 2.0, 3.0, 4.0], dtype=torch.float64)
    r = torch.tensor([5.0, 6.0, 7.0, 8.0], dtype=torch.float64)
    assert torch.equal(hamilton_product(q, r), torch.tensor([-60.0, 12.0, 30.0, 24.0], dtype=torch.float64))
    # the misprinted j term (Q_h R_e instead of Q_h R_f) would give 3*5 + 4*5 + 1*7 - 2*8 = 26, not 30
    assert hamilton_product(q, r)[2].item() == 3 * 5 + 4 * 6 + 1 * 7 - 2 * 8


def test_hamilton_product_norm_property_and_scipy_composition():
    gen = torch.Generator().manual_seed(0)
    p, q = torch.randn(2, 64, 4, generator=gen, dtype=torch.float64)
    pq = hamilton_product(p, q)
    torch.testing.assert_close(pq.norm(dim=-1), p.norm(dim=-1) * q.norm(dim=-1))
    # unit quaternions compose rotations: R(p q) = R(p) R(q) (scipy stores x, y, z, w)
    pu, qu = F.normalize(p, dim=-1), F.normalize(q, dim=-1)
    prod = hamilton_product(pu, qu).numpy()
    expected = Rotation.from_quat(pu.numpy()[:, [1, 2, 3, 0]]) * Rotation.from_quat(
        qu.numpy()[:, [1, 2, 3, 0]]
    )
    np.testing.assert_allclose(
        Rotation.from_quat(prod[:, [1, 2, 3, 0]]).as_matrix(), expected.as_matrix(), atol=1e-12
    )
    # the conjugate gives the squared norm: Re(q q*) = |q|^2, imaginary part 0
    qq = hamilton_product(q, quaternion_conjugate(q))
    torch.testing.assert_close(qq[:, 0], q.square().sum(-1))
    torch.testing.assert_close(qq[:, 1:], torch.zeros_like(qq[:, 1:]))


def test_quaternion_parameterisation_254_to_63_round_trip():
    motion, music = torch.randn(2, 10, 219), torch.randn(2, 10, 35)
    x = torch.cat([motion, music], dim=-1)
    quats = quaternion_parameterise(x)
    assert quats.shape == (2, 10, 63, 4)
    assert torch.equal(quats[0, 0, 1], x[0, 0, 4:8])  # the second quaternion is values 4..7
    assert torch.equal(quaternion_flatten(quats), x[..., :252])  # the last two values are dropped
    y = torch.randn(3, 16)
    assert torch.equal(quaternion_flatten(quaternion_parameterise(y)), y)
    with pytest.raises(ValueError, match="at least 4"):
        quaternion_parameterise(torch.randn(3))


def test_spin_position_embedding_matches_rotation_matrix_and_is_relative():
    d = 8
    rope = SpinPositionEmbedding(d, base=100.0)
    gen = torch.Generator().manual_seed(1)
    q, k = torch.randn(2, 12, d, generator=gen, dtype=torch.float64)
    cos, sin = rope.cos_sin(12, torch.float64, q.device)
    rq = apply_rotary(q, cos, sin)
    # Eq. 22 by hand for pair i = 1 at position s = 5: R(s theta_1) (q_2, q_3)^T, theta_1 = 100^(-2/8)
    s, theta = 5, 100.0 ** (-2 / 8)
    rot = torch.tensor(
        [[math.cos(s * theta), -math.sin(s * theta)], [math.sin(s * theta), math.cos(s * theta)]]
    )
    torch.testing.assert_close(rq[s, 2:4], rot.double() @ q[s, 2:4])
    # Eq. 11/24: <O_q(x_s, s), O_k(x_t, t)> = g(x_s, x_t, s - t): the same vectors at shifted positions
    x_q, x_k = q[0], k[0]

    def score(ps, pt):
        c, sn = rope.cos_sin(20, torch.float64, q.device)
        return (apply_rotary(x_q, c[ps], sn[ps]) * apply_rotary(x_k, c[pt], sn[pt])).sum()

    torch.testing.assert_close(score(7, 3), score(15, 11))
    torch.testing.assert_close(score(2, 9), score(10, 17))
    assert not torch.allclose(score(7, 3), score(7, 4))


def test_qra_reduces_to_scaled_dot_product_attention():
    gen = torch.Generator().manual_seed(2)
    for d in (8, 10):  # 10: two channels beyond whole quaternions
        q = torch.randn(2, 3, 6, d, generator=gen, dtype=torch.float64)
        k, v = torch.randn(2, 2, 3, 9, d, generator=gen, dtype=torch.float64)
        zeros_q, zeros_k = (
            torch.zeros(2, 3, 6, 1, dtype=torch.float64),
            torch.zeros(2, 3, 9, 1, dtype=torch.float64),
        )
        got = quaternion_rotary_attention(q, k, v, zeros_q, zeros_k)
        weights = torch.softmax(q @ k.transpose(-1, -2) / math.sqrt(d), dim=-1)  # canonical attention by hand
        torch.testing.assert_close(got, weights @ v)
    # the module with zeroed frequency/phase convolutions (omega = ReLU(0) = 0, theta = pi tanh(0) = 0), P = 1
    attn = QuaternionRotaryAttention(16, 2, num_periods=1).double().eval()
    for conv in (attn.q_freq_phase, attn.k_freq_phase):
        torch.nn.init.zeros_(conv.weight)
        torch.nn.init.zeros_(conv.bias)
    x = torch.randn(2, 5, 16, generator=gen, dtype=torch.float64)
    mha = torch.nn.MultiheadAttention(16, 2, batch_first=True).double()
    with torch.no_grad():
        mha.in_proj_weight.copy_(torch.cat([attn.q_proj.weight, attn.k_proj.weight, attn.v_proj.weight]))
        mha.in_proj_bias.copy_(torch.cat([attn.q_proj.bias, attn.k_proj.bias, attn.v_proj.bias]))
        mha.out_proj.weight.copy_(attn.out.weight)
        mha.out_proj.bias.copy_(attn.out.bias)
    torch.testing.assert_close(attn(x), mha(x, x, x, need_weights=False)[0])


def test_qra_series_rotation_by_hand():
    # one query quaternion q, one key quaternion k, P = 1: score = Re[(q e^{i a}) (k e^{j b})^*]
    q = torch.tensor([0.3, -1.2, 0.5, 2.0], dtype=torch.float64).view(1, 1, 4)
    k = torch.tensor([1.1, 0.4, -0.7, 0.2], dtype=torch.float64).view(1, 1, 4)
    a, b = 0.7, -1.3
    v = torch.tensor([[[2.0], [5.0]]], dtype=torch.float64)  # two keys: k and the zero quaternion
    keys = torch.cat([k, torch.zeros_like(k)], dim=1)
    # rotate by hand: q e^{ia} with e^{ia} = (cos a, sin a, 0, 0); k e^{jb} with (cos b, 0, sin b, 0)
    qe, qf, qg, qh = q.flatten().tolist()
    ca, sa = math.cos(a), math.sin(a)
    q_rot = [qe * ca - qf * sa, qf * ca + qe * sa, qg * ca + qh * sa, qh * ca - qg * sa]
    ke, kf, kg, kh = k.flatten().tolist()
    cb, sb = math.cos(b), math.sin(b)
    k_rot = [ke * cb - kg * sb, kf * cb - kh * sb, kg * cb + ke * sb, kh * cb + kf * sb]  # k j = i, i j = k
    s = sum(x * y for x, y in zip(q_rot, k_rot, strict=True)) / 2.0  # / (P sqrt(d)), d = 4
    w = math.exp(s) / (math.exp(s) + 1.0)
    got = quaternion_rotary_attention(
        q,
        keys,
        v,
        torch.full((1, 1, 1), a, dtype=torch.float64),
        torch.full((1, 2, 1), b, dtype=torch.float64),
    )
    assert got.item() == pytest.approx(w * 2.0 + (1 - w) * 5.0, abs=1e-12)


def test_qra_num_queries_equals_first_rows():
    torch.manual_seed(3)
    attn = QuaternionRotaryAttention(16, 2, num_periods=3, kernel_size=5).eval()
    x = torch.randn(2, 11, 16)
    torch.testing.assert_close(attn(x, num_queries=2), attn(x)[:, :2])


def test_motion_representation_round_trip_and_projection():
    gen = torch.Generator().manual_seed(4)
    poses = torch.randn(5, 24, 3, generator=gen, dtype=torch.float64)
    root = torch.randn(5, 3, generator=gen, dtype=torch.float64)
    feats = smpl_to_features(poses, root)
    assert feats.shape == (5, 219)
    # rows of the first joint's matrix, from scipy
    np.testing.assert_allclose(
        feats[0, 3:12].numpy(), Rotation.from_rotvec(poses[0, 0].numpy()).as_matrix().ravel()
    )
    back_poses, back_root = features_to_smpl(feats)
    torch.testing.assert_close(smpl_to_features(back_poses, back_root), feats)
    # the nearest rotation of R S (S symmetric positive definite) is R: scipy's polar decomposition
    rng = np.random.default_rng(0)
    r0 = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    a = rng.normal(size=(3, 3))
    m = r0 @ (a @ a.T + 0.5 * np.eye(3))
    np.testing.assert_allclose(polar(m)[0], r0, atol=1e-12)  # independent check of the premise
    np.testing.assert_allclose(nearest_rotation(torch.from_numpy(m)).numpy(), r0, atol=1e-10)
    # a reflection-contaminated matrix still maps to a proper rotation (det +1)
    assert torch.det(nearest_rotation(torch.from_numpy(-m))).item() == pytest.approx(1.0)
    assert features_to_joints(feats).shape == (5, 24, 3)


def _tiny(backbone=None, **kw) -> QEAN:
    sizes = dict(
        hidden=32, heads=2, motion_layers=1, audio_layers=1, cross_layers=2, mlp_dim=64, num_periods=2,
        seed_frames=12, music_frames=24, predict_frames=4, dropout=0.0,
    )  # fmt: skip
    return QEAN(QEANConfig(**(sizes | kw)), backbone).eval()


def test_model_output_shape_and_mamba_variant():
    torch.manual_seed(0)
    model = _tiny()
    assert model(torch.randn(3, 12, 219), torch.randn(3, 24, 35)).shape == (3, 4, 219)
    backbone = SkeletonMambaConfig(
        dim=16, depth=1, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    mamba = _tiny(backbone)
    assert mamba(torch.randn(2, 12, 219), torch.randn(2, 24, 35)).shape == (2, 4, 219)
    assert any("backbone" in name for name, _ in mamba.named_parameters())


@pytest.mark.parametrize(
    "variant", ["one_layer", "two_layers", "learned_positions", "mamba_encoder", "smoothing"]
)
def test_generation_length_and_fast_equals_plain(variant):
    torch.manual_seed(0)
    backbone = SkeletonMambaConfig(
        dim=16, depth=1, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    kwargs = {
        "one_layer": {},
        "two_layers": {"motion_layers": 2, "audio_layers": 2},  # reused first block + a recomputed one
        "learned_positions": {"learned_positions": True},  # per-window embeddings: no per-token reuse
        "mamba_encoder": {"backbone": backbone},  # SkeletonMamba motion encoder runs per window
        "smoothing": {"smoothing_stages": 3, "smoothing_decay": 0.5},  # the output low-pass
    }[variant]
    model = _tiny(**kwargs).double()
    seed = torch.randn(2, 20, 219, dtype=torch.float64)
    music = torch.randn(2, 30, 35, dtype=torch.float64)  # shorter than needed: zero-padded
    plain = generate_plain(model, seed, music, num_frames=25)
    fast = generate_fast(model, seed, music, num_frames=25, audio_chunk=7)
    assert plain.shape == fast.shape == (2, 25, 219)
    torch.testing.assert_close(fast, plain, rtol=0, atol=1e-10)
    # the first step uses the last 12 seed frames and music [0, 24)
    torch.testing.assert_close(plain[:, 0], model(seed[:, -12:], music[:, :24])[:, 0])
    # step 5 sees seed frames 13..19 and generated frames 0..4, music [5, 29); step 24 generated frames
    # 12..23 and music [24, 48): frames 24..29 of the track and 18 zero frames
    torch.testing.assert_close(
        plain[:, 5], model(torch.cat([seed[:, 13:], plain[:, :5]], 1), music[:, 5:29])[:, 0]
    )
    padded = torch.cat([music[:, 24:], music.new_zeros(2, 18, 35)], dim=1)
    torch.testing.assert_close(plain[:, 24], model(plain[:, 12:24], padded)[:, 0])
    with pytest.raises(ValueError, match="seed must be"):
        generate_fast(model, seed[:, :5], music, num_frames=3)


def test_output_low_pass_carries_on_from_the_window_in_training_and_generation():
    """smoothing_stages: y_t = (1 - d)^K x_t - sum_j C(K, j) (-d)^j y_{t-j} on the head's outputs x, the y
    before the window's end being its frames; written out here for K = 2:
    y_t = (1 - d)^2 x_t + 2 d y_{t-1} - d^2 y_{t-2}."""
    torch.manual_seed(0)
    d = 0.6
    smooth = _tiny(smoothing_stages=2, smoothing_decay=d).double()
    plain = _tiny().double()
    plain.load_state_dict(smooth.state_dict())  # the same weights, [QEAN]'s frames
    assert QEANConfig().smoothing_stages == 0  # the paper's behaviour is the default
    seed = torch.randn(2, 12, 219, dtype=torch.float64)
    music = torch.randn(2, 40, 35, dtype=torch.float64)

    def by_hand(x, past):
        y = [past[:, -2], past[:, -1]]
        for t in range(x.shape[1]):
            y.append((1 - d) ** 2 * x[:, t] + 2 * d * y[-1] - d * d * y[-2])
        return torch.stack(y[2:], dim=1)

    want = by_hand(plain(seed, music[:, :24]), seed)
    torch.testing.assert_close(smooth(seed, music[:, :24]), want, rtol=0, atol=1e-12)
    # generation: each kept frame is the low-pass carried on from the two frames before it
    frames = generate_fast(smooth, seed, music, num_frames=3, audio_chunk=2)
    window = seed
    for i in range(3):
        step = by_hand(plain(window, music[:, i : i + 24])[:, :1], window)
        torch.testing.assert_close(frames[:, i : i + 1], step, rtol=0, atol=1e-12)
        window = torch.cat([window[:, 1:], step], dim=1)
    with pytest.raises(ValueError, match="smoothing_stages"):
        _tiny(smoothing_stages=13)


def test_series_rotation_is_the_hamilton_product_with_the_unit():
    gen = torch.Generator().manual_seed(5)
    x = torch.randn(3, 7, 10, generator=gen, dtype=torch.float64)  # 2 quaternions + 2 leftover channels
    phase = torch.randn(3, 7, 4, generator=gen, dtype=torch.float64)
    for axis in (1, 2):
        unit = torch.zeros(3, 7, 4, 4, dtype=torch.float64)
        unit[..., 0], unit[..., axis] = phase.cos(), phase.sin()
        want = hamilton_product(x[..., :8].reshape(3, 7, 1, 2, 4), unit[..., None, :])  # (3, 7, P, 2, 4)
        torch.testing.assert_close(series_rotation(x, phase, axis), want.flatten(-2), rtol=0, atol=1e-15)


def test_spin_position_embedding_at_an_offset_keeps_the_scores():
    # the fast path projects tokens at absolute positions: window scores equal those at positions 0..T-1
    rope = SpinPositionEmbedding(8)
    gen = torch.Generator().manual_seed(6)
    q, k = torch.randn(2, 9, 8, generator=gen, dtype=torch.float64)
    at_zero = rope.rotate(q) @ rope.rotate(k).T
    torch.testing.assert_close(rope.rotate(q, offset=1234) @ rope.rotate(k, offset=1234).T, at_zero)
    cos, sin = rope.cos_sin(1243, torch.float64, q.device)
    torch.testing.assert_close(rope.rotate(q, offset=1234), apply_rotary(q, cos[1234:], sin[1234:]))
