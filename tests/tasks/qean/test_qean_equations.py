"""QEAN Eq. 25 against an independent computation: omega = ReLU(Conv1d), theta = pi tanh(Conv1d), and the
angles 2 pi omega pos + theta with pos^Q = [0 .. N-1] / N, pos^K = [0 .. M-1] / M ([QEAN] section 3.4)."""

from __future__ import annotations

import math

import numpy as np
import torch
from einops import rearrange

from skeleton_mamba.tasks.qean.attention import QuaternionRotaryAttention, quaternion_rotary_attention


def _conv_same(x: np.ndarray, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """Zero-padded 'same' 1D convolution by loops: x (T, C_in), weight (C_out, C_in, K) -> (T, C_out)."""
    t_len, k = x.shape[0], weight.shape[-1]
    out = np.tile(bias, (t_len, 1)).astype(np.float64)
    for t in range(t_len):
        for j in range(k):
            s = t + j - k // 2
            if 0 <= s < t_len:
                out[t] += weight[:, :, j] @ x[s]
    return out


def _angles(x: np.ndarray, conv: torch.nn.Conv1d, heads: int, periods: int, length: int) -> np.ndarray:
    """Eq. 25 by hand for one sequence x (T, dim) -> (heads, T, P)."""
    out = _conv_same(x, conv.weight.detach().numpy(), conv.bias.detach().numpy())
    pre_omega = out[:, : heads * periods].reshape(-1, heads, periods)
    pre_theta = out[:, heads * periods :].reshape(-1, heads, periods)
    omega = np.maximum(pre_omega, 0.0)  # ReLU: frequencies in [0, inf)
    theta = math.pi * np.tanh(pre_theta)  # phases in (-pi, pi)
    pos = np.arange(x.shape[0])[:, None, None] / length
    return (2 * math.pi * omega * pos + theta).transpose(1, 0, 2)


def _attention() -> QuaternionRotaryAttention:
    torch.manual_seed(0)
    attn = QuaternionRotaryAttention(16, 2, num_periods=3).double().eval()
    with torch.no_grad():  # large pre-activations: tanh saturates, ReLU clips about half of them
        for conv in (attn.q_freq_phase, attn.k_freq_phase):
            conv.weight.mul_(8.0)
            conv.bias.normal_(0.0, 2.0)
    return attn


def test_eq25_frequencies_and_phases_by_hand():
    attn = _attention()
    x = torch.randn(2, 7, 16, dtype=torch.float64)
    got = attn._phases(x, attn.q_freq_phase, length=7).detach().numpy()
    for b in range(2):
        expected = _angles(x[b].numpy(), attn.q_freq_phase, 2, 3, 7)
        np.testing.assert_allclose(got[b], expected, rtol=1e-10, atol=1e-10)
    pre = _conv_same(
        x[0].numpy(), attn.q_freq_phase.weight.detach().numpy(), attn.q_freq_phase.bias.detach().numpy()
    )
    assert (pre[:, :6] < 0).mean() > 0.2 and (np.abs(pre[:, 6:]) > 2).mean() > 0.2  # ReLU and tanh matter


def test_cross_attention_uses_query_and_key_positions_over_their_own_lengths():
    attn = _attention()
    x, context = torch.randn(1, 5, 16, dtype=torch.float64), torch.randn(1, 9, 16, dtype=torch.float64)
    with torch.no_grad():
        out = attn(x, context)
        q, k, v = attn.q_proj(x), attn.k_proj(context), attn.v_proj(context)
        phase_q = torch.from_numpy(_angles(q[0].numpy(), attn.q_freq_phase, 2, 3, 5))[None]  # pos^Q = n / 5
        phase_k = torch.from_numpy(_angles(k[0].numpy(), attn.k_freq_phase, 2, 3, 9))[None]  # pos^K = m / 9
        split = lambda y: rearrange(y, "b t (h d) -> b h t d", h=2)  # noqa: E731
        y = quaternion_rotary_attention(split(q), split(k), split(v), phase_q, phase_k)
        by_hand = attn.out(rearrange(y, "b h t d -> b t (h d)"))
    torch.testing.assert_close(out, by_hand)
