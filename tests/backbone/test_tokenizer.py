"""Human Tokenizer and its inverse, against index loops written out by hand."""

import pytest
import torch

from skeleton_mamba.skeletons import SKELETONS, SMPL24
from skeleton_mamba.tokenizer import HumanTokenizer, InverseHumanTokenizer


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_tokenizer_gathers_group_joints_in_order(name):
    sk = SKELETONS[name]
    d = 3
    x = torch.randn(2, 4, sk.num_joints, d)
    tokens = HumanTokenizer(sk.groups)(x)
    assert tokens.shape == (2, 4, sk.num_groups, sk.group_size * d)
    for g, group in enumerate(sk.groups):
        for p, joint in enumerate(group):
            assert torch.equal(tokens[:, :, g, p * d : (p + 1) * d], x[:, :, joint])


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_round_trip_restores_every_joint(name):
    sk = SKELETONS[name]
    x = torch.randn(2, 5, sk.num_joints, 4)
    tokens = HumanTokenizer(sk.groups)(x).unflatten(-1, (sk.group_size, 4))
    back = InverseHumanTokenizer(sk.groups, sk.num_joints)(tokens)
    torch.testing.assert_close(back, x)


def test_inverse_averages_joints_shared_by_groups():
    # SMPL-24: joints 0, 3 and 9 occur in three groups each; give every copy a different value.
    tokens = torch.randn(1, 1, 5, 6, 2)
    out = InverseHumanTokenizer(SMPL24.groups, 24)(tokens)
    for joint in range(24):
        copies = [
            tokens[0, 0, g, p] for g, grp in enumerate(SMPL24.groups) for p, j in enumerate(grp) if j == joint
        ]
        expected = sum(copies) / len(copies)
        torch.testing.assert_close(out[0, 0, joint], expected)
    assert sum(1 for grp in SMPL24.groups for j in grp if j == 9) == 3


def test_bad_groups_are_refused():
    with pytest.raises(ValueError, match="same size"):
        HumanTokenizer([(0, 1), (2,)])
    with pytest.raises(ValueError, match="belong to no group"):
        InverseHumanTokenizer([(0, 1), (1, 2)], 4)
