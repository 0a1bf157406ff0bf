"""Group Scan, Joint Scan and Temporal Scan against independent loop constructions."""

import pytest
import torch

from skeleton_mamba.config import MixerConfig
from skeleton_mamba.group_scan import GroupScan
from skeleton_mamba.joint_scan import JointScan
from skeleton_mamba.skeletons import DEFAULT_GROUP_PATHS, GROUP_MIRROR
from skeleton_mamba.temporal_scan import TemporalScan, check_prefix_mask, valid_prefix_reversal

SMALL = MixerConfig(d_state=8, headdim=8, chunk_size=16)


def _unpermute(y_path, path):
    """y_path[..., k, :] belongs to group path[k]; return it in group order."""
    out = torch.empty_like(y_path)
    for k, grp in enumerate(path):
        out[..., grp, :] = y_path[..., k, :]
    return out


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)


def test_group_scan_eq13_concatenates_paths_into_one_sequence():
    gs = GroupScan(16, DEFAULT_GROUP_PATHS, shared=False, mixer=SMALL)
    g = torch.randn(2, 3, 5, 16)
    flat = g.reshape(6, 5, 16)
    seq = torch.cat([flat[:, list(p)] for p in DEFAULT_GROUP_PATHS], dim=1)  # (6, 40, 16)
    y = gs.mixer(seq)
    parts = [_unpermute(y[:, 5 * i : 5 * i + 5], p) for i, p in enumerate(DEFAULT_GROUP_PATHS)]
    expected = torch.stack(parts).mean(0).reshape(2, 3, 5, 16)
    torch.testing.assert_close(gs(g), expected)


def test_group_scan_eq18_scans_each_path_with_shared_weights():
    gs = GroupScan(16, DEFAULT_GROUP_PATHS, shared=True, mixer=SMALL)
    g = torch.randn(4, 5, 16)
    parts = [_unpermute(gs.mixer(g[:, list(p)]), p) for p in DEFAULT_GROUP_PATHS]
    torch.testing.assert_close(gs(g), torch.stack(parts).mean(0))


def test_shared_group_scan_is_equivariant_under_the_body_mirror():
    # Eq. 20: with a path set closed under rho, F(g^rho) = F(g)^rho.
    gs = GroupScan(16, DEFAULT_GROUP_PATHS, shared=True, mixer=SMALL).double()
    g = torch.randn(3, 2, 5, 16, dtype=torch.float64)
    rho = list(GROUP_MIRROR)
    # g^rho: group k of the mirrored body is group rho[k] of the original.
    torch.testing.assert_close(gs(g[:, :, rho]), gs(g)[:, :, rho], rtol=1e-10, atol=1e-10)


def test_equivariance_needs_a_closed_path_set():
    # The test above can fail: one path alone is not closed under the mirror.
    gs = GroupScan(16, [(1, 2, 0, 3, 4)], shared=True, mixer=SMALL).double()
    g = torch.randn(3, 5, 16, dtype=torch.float64)
    rho = list(GROUP_MIRROR)
    assert not torch.allclose(gs(g[:, rho]), gs(g)[:, rho], atol=1e-6)
    # ... and Eq. 13's concatenation is not equivariant even with the closed set (Eq. 17).
    gs13 = GroupScan(16, DEFAULT_GROUP_PATHS, shared=False, mixer=SMALL).double()
    assert not torch.allclose(gs13(g[:, rho]), gs13(g)[:, rho], atol=1e-6)


def test_group_scan_rejects_non_permutations():
    with pytest.raises(ValueError, match="permutation"):
        GroupScan(8, [(0, 0, 1)], mixer=SMALL)


def test_joint_scan_shares_one_mixer_across_groups():
    js = JointScan(8, group_size=6, mixer=SMALL)
    g = torch.randn(2, 3, 5, 48)
    out = js(g)
    assert out.shape == (2, 3, 5, 6, 8)
    for k in range(5):
        tokens = js.split(g[:, :, k]).reshape(6, 6, 8)  # (B*T, P, D)
        torch.testing.assert_close(out[:, :, k].reshape(6, 6, 8), js.mixer(tokens))


def test_valid_prefix_reversal_hand_values():
    mask = torch.tensor([[True, True, True, False, False], [True, True, True, True, True]])
    assert valid_prefix_reversal(mask).tolist() == [[2, 1, 0, 3, 4], [4, 3, 2, 1, 0]]
    with pytest.raises(ValueError, match="prefix"):
        check_prefix_mask(torch.tensor([[True, False, True]]))


def test_temporal_scan_is_forward_plus_reversed_backward():
    ts = TemporalScan(16, mixer=SMALL)
    x = torch.randn(2, 11, 3, 16)
    seq = x.permute(0, 2, 1, 3).reshape(6, 11, 16)
    expected = ts.proj(ts.forward_mixer(seq) + ts.backward_mixer(seq.flip(1)).flip(1))
    torch.testing.assert_close(ts(x), expected.reshape(2, 3, 11, 16).permute(0, 2, 1, 3))


def test_padding_cannot_reach_valid_frames_in_either_direction():
    ts = TemporalScan(16, mixer=SMALL)
    lengths = [20, 13, 5]
    x = torch.randn(3, 20, 4, 16)
    mask = torch.arange(20)[None] < torch.tensor(lengths)[:, None]
    out = ts(x, mask)
    garbage = x.clone()
    garbage[~mask] = 1e3 * torch.randn(int((~mask).sum()), 4, 16)
    out_garbage = ts(garbage, mask)
    for b, n in enumerate(lengths):
        alone = ts(x[b : b + 1, :n])  # the unpadded sequence on its own
        torch.testing.assert_close(out[b, :n], alone[0], rtol=1e-4, atol=1e-5)
        torch.testing.assert_close(out_garbage[b, :n], alone[0], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("shared", [False, True])
def test_group_scan_projection_sharing_keeps_the_gradients_of_the_direct_scan(shared):
    """Projecting distinct group tokens once must not change any gradient of Eq. 13 / Eq. 18."""
    gs = GroupScan(16, DEFAULT_GROUP_PATHS, shared=shared, mixer=SMALL).double()
    g = torch.randn(3, 5, 16, dtype=torch.float64, requires_grad=True)
    gs(g).square().sum().backward()
    fast = [g.grad.clone()] + [p.grad.clone() for p in gs.parameters()]
    g.grad = None
    gs.zero_grad()
    if shared:
        parts = [_unpermute(gs.mixer(g[:, list(p)]), p) for p in DEFAULT_GROUP_PATHS]
    else:
        y = gs.mixer(torch.cat([g[:, list(p)] for p in DEFAULT_GROUP_PATHS], dim=1))
        parts = [_unpermute(y[:, 5 * i : 5 * i + 5], p) for i, p in enumerate(DEFAULT_GROUP_PATHS)]
    torch.stack(parts).mean(0).square().sum().backward()
    direct = [g.grad] + [p.grad for p in gs.parameters()]
    for a, b in zip(fast, direct, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-12)
