"""The causal output low-pass (``tasks/training/causal_smoothing.py``): against scipy's IIR filter with the
stages at rest on the first frame, its frequency response against the measured one, step = sequence, its
recurrence over its last outputs (QEAN's form) against scipy's cascade carried on, and the dancer's step equal
to its forward with the low-pass (also through ``DancerState``)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import signal

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.stream.model import StreamDancer
from skeleton_mamba.tasks.training.causal_smoothing import CausalSmoothing


def _scipy_cascade(x: np.ndarray, stages: int, decay: float) -> np.ndarray:
    """``stages`` first-order IIR filters y_t = d y_{t-1} + (1 - d) x_t along axis 1, each at rest on x_0."""
    b, a = [1.0 - decay], [1.0, -decay]
    y = x
    for _ in range(stages):
        zi = signal.lfilter_zi(b, a)  # the state of a filter at rest on a unit input
        y, _ = signal.lfilter(b, a, y, axis=1, zi=zi[None, :, None] * y[:, :1])
    return y


@pytest.mark.parametrize(("stages", "decay"), [(1, 0.5), (4, 0.6), (8, 0.6), (3, 0.9)])
def test_sequence_is_scipys_cascade_at_rest_on_the_first_frame(stages, decay):
    x = np.random.default_rng(stages).standard_normal((3, 200, 5)) + 2.0
    ours = CausalSmoothing(stages, decay).sequence(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(ours, _scipy_cascade(x, stages, decay), atol=1e-8)


@pytest.mark.parametrize(("stages", "decay"), [(1, 0.5), (3, 0.5), (8, 0.6)])
def test_continued_is_the_cascade_carried_on_from_its_last_outputs(stages, decay):
    """The all-pole recurrence over the last K outputs (QEAN's form) continues scipy's cascade exactly."""
    x = np.random.default_rng(stages).standard_normal((2, 120, 3))
    full = _scipy_cascade(x, stages, decay)
    cut = 70
    ours = CausalSmoothing(stages, decay).continued(
        torch.from_numpy(x[:, cut:]), torch.from_numpy(full[:, :cut])
    )
    np.testing.assert_allclose(ours.numpy(), full[:, cut:], atol=1e-9)
    with pytest.raises(ValueError, match="past must be"):
        CausalSmoothing(stages, decay).continued(torch.zeros(2, 4, 3), torch.zeros(2, stages - 1, 3))
    identity = CausalSmoothing(0)
    assert identity.continued(torch.ones(1, 2, 3), torch.zeros(1, 0, 3)).eq(1).all()


def test_step_equals_sequence_and_a_constant_passes_unchanged():
    smoothing = CausalSmoothing(6, 0.7)
    x = torch.randn(2, 50, 4, 3, dtype=torch.float64)
    state, frames = None, []
    for t in range(x.shape[1]):
        y, state = smoothing.step(x[:, t], state)
        frames.append(y)
    torch.testing.assert_close(torch.stack(frames, 1), smoothing.sequence(x), atol=1e-10, rtol=0)
    assert state.shape == (6, 2, 4, 3)
    # a first frame says so with started False or a 0 tensor: any stored stages are ignored
    for started in (False, torch.tensor(0.0, dtype=torch.float64)):
        first, _ = smoothing.step(x[:, 0], torch.full_like(state, 9.0), started)
        torch.testing.assert_close(first, x[:, 0])
    later, _ = smoothing.step(x[:, 0], state, torch.tensor(1.0, dtype=torch.float64))
    torch.testing.assert_close(later, smoothing.step(x[:, 0], state)[0])
    constant = torch.full((1, 30, 2), 3.5, dtype=torch.float64)
    torch.testing.assert_close(smoothing.sequence(constant), constant)


def test_power_gain_is_the_measured_response_and_zero_stages_is_the_identity():
    smoothing = CausalSmoothing(8, 0.6)
    frames = 4096
    impulse = torch.zeros(1, frames, 1, dtype=torch.float64)
    impulse[0, 100] = 1.0  # the response to an impulse after a rest at 0
    response = smoothing.sequence(impulse)[0, 100:, 0]
    freqs = torch.fft.rfftfreq(response.shape[0], dtype=torch.float64)
    measured = torch.fft.rfft(response).abs().square()
    torch.testing.assert_close(measured, smoothing.power_gain(freqs), atol=1e-9, rtol=1e-6)
    # at 30 fps: 1.5 Hz keeps 8 %, 6 Hz less than 1e-6 of its power
    gain = smoothing.power_gain(torch.tensor([1.5 / 30, 6.0 / 30], dtype=torch.float64))
    assert 0.05 < gain[0] < 0.12 and gain[1] < 1e-6
    x = torch.randn(2, 9, 3)
    assert CausalSmoothing(0).sequence(x) is x
    with pytest.raises(ValueError, match="decay"):
        CausalSmoothing(2, 1.0)
    with pytest.raises(ValueError, match="stages"):
        CausalSmoothing(17)


def test_dancer_step_equals_forward_with_the_low_pass():
    torch.manual_seed(0)
    tiny = SkeletonMambaConfig(
        dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    plain = StreamDancer(tiny, music_dim=6).eval()
    smooth = StreamDancer(tiny, music_dim=6, smoothing_stages=8, smoothing_decay=0.6).eval()
    smooth.load_state_dict(plain.state_dict())
    prev, music = torch.randn(2, 40, 24, 12), torch.randn(2, 40, 6)
    with torch.no_grad():
        raw, full = plain(prev, music), smooth(prev, music)
        state, frames = smooth.init_state(2), []
        for t in range(40):
            pose, state = smooth.step(prev[:, t], music[:, t], state)
            frames.append(pose)
    torch.testing.assert_close(full, CausalSmoothing(8, 0.6).sequence(raw))
    torch.testing.assert_close(torch.stack(frames, 1), full, atol=1e-5, rtol=1e-5)
    assert state.frames == 40 and state.smoothing.shape == (8, 2, 24, 12) and state.started
    assert state.nbytes == smooth.init_state(2).nbytes == plain.init_state(2).nbytes + 8 * 2 * 24 * 12 * 4
    state.reset()
    assert not state.started and state.frames == 0 and not state.smoothing.any()
    with torch.no_grad():  # after a reset the stream starts again as new
        again, _ = smooth.step(prev[:, 0], music[:, 0], state)
    torch.testing.assert_close(again, full[:, 0], atol=1e-5, rtol=1e-5)
