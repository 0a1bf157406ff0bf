"""Slicing frames and joint sequences on a CPU (``skeleton_mamba.runtime.slicing``) must not change
results."""

import dataclasses

import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig, TemporalScan
from skeleton_mamba.runtime.slicing import map_slices, slice_length

TINY_MIXER = MixerConfig(d_state=8, headdim=8, chunk_size=16)


def test_slice_length_follows_the_budget_and_never_slices_off_the_cpu():
    x = torch.zeros(10, 3)
    assert slice_length(x, 0, 100, 350) == 3
    assert slice_length(x, 0, 100, 50) == 1  # at least one index per slice
    assert slice_length(x, 0, 100, 10**6) == 10
    assert slice_length(x, 0, 100, None) == 10
    assert slice_length(torch.zeros(10, 3, device="meta"), 0, 100, 350) == 10


def test_map_slices_calls_once_per_slice_and_concatenates_in_order():
    a, b = torch.arange(10.0).reshape(1, 10), torch.arange(10.0, 20.0).reshape(1, 10)
    calls = []

    def fn(x, y):
        calls.append(x.shape[1])
        return x * 2 + y

    out = map_slices(fn, 1, 4, a, b)
    assert calls == [4, 4, 2]
    assert out.tolist() == [[2 * i + 10 + i for i in range(10)]]
    calls.clear()
    map_slices(fn, 1, 10, a, b)
    assert calls == [10]


@pytest.mark.parametrize("with_context", [False, True])
def test_sliced_backbone_equals_one_call_with_its_gradients(with_context):
    """Many tiny slices (budget of a few elements) against no slicing, float64, with padding."""
    torch.manual_seed(0)
    cfg = SkeletonMambaConfig(
        skeleton="smpl24",
        in_channels=3,
        dim=16,
        depth=2,
        mlp_dim=32,
        context_dim=8 if with_context else None,
        mixer=TINY_MIXER,
        cpu_slice_elements=None,
    )
    whole = SkeletonMamba(cfg).double()
    sliced = SkeletonMamba(dataclasses.replace(cfg, cpu_slice_elements=1)).double()
    sliced.load_state_dict(whole.state_dict())
    x = torch.randn(2, 23, 24, 3, dtype=torch.float64)
    mask = torch.arange(23)[None] < torch.tensor([[23], [15]])
    kwargs = {"context": torch.randn(2, 5, 8, dtype=torch.float64)} if with_context else {}
    calls = []
    sliced.blocks[0].group_scan.register_forward_hook(lambda m, i, o: calls.append(i[0].shape[1]))
    outs, grads = [], []
    for model in (whole, sliced):
        y = model(x, mask, **kwargs)
        (y * torch.linspace(-1, 1, y.numel(), dtype=torch.float64).reshape(y.shape)).sum().backward()
        outs.append(y)
        grads.append(torch.cat([p.grad.flatten() for p in model.parameters()]))
    assert calls == [1] * 23  # one frame per slice
    torch.testing.assert_close(outs[1], outs[0], rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(grads[1], grads[0], rtol=1e-10, atol=1e-12)


def test_temporal_scan_slices_joint_sequences():
    torch.manual_seed(0)
    whole = TemporalScan(16, mixer=TINY_MIXER).double()
    sliced = TemporalScan(16, mixer=TINY_MIXER, slice_elements=1).double()
    sliced.load_state_dict(whole.state_dict())
    x = torch.randn(3, 20, 4, 16, dtype=torch.float64)
    mask = torch.arange(20)[None] < torch.tensor([[20], [13], [5]])
    calls = []
    sliced.forward_mixer.register_forward_hook(lambda m, i, o: calls.append(i[0].shape[0]))
    torch.testing.assert_close(sliced(x, mask), whole(x, mask), rtol=1e-12, atol=1e-12)
    assert calls == [1] * 12  # one joint sequence per slice: 3 batch x 4 joints
