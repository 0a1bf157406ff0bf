"""Skeleton definitions: trees, mirror maps and the mirror symmetry of the tokenizer groups."""

import pytest

from skeleton_mamba.skeletons import DEFAULT_GROUP_PATHS, GROUP_MIRROR, SKELETONS, Skeleton, get_skeleton


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_mirror_maps_limb_groups_onto_each_other(name):
    sk = SKELETONS[name]
    # Under the left/right mirror, group g becomes group GROUP_MIRROR[g] position by position.
    for g in (1, 2, 3, 4):
        mirrored = tuple(sk.mirror[j] for j in sk.groups[g])
        assert mirrored == sk.groups[GROUP_MIRROR[g]]
    # Mirrored joint names swap left and right.
    for i, m in enumerate(sk.mirror):
        a, b = sk.joint_names[i], sk.joint_names[m]
        assert a.replace("left", "X").replace("right", "left").replace("X", "right") == b


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_parents_form_a_tree_reaching_the_root(name):
    sk = SKELETONS[name]
    order = sk.topological_order
    assert sorted(order) == list(range(sk.num_joints))
    pos = {j: i for i, j in enumerate(order)}
    for j, p in enumerate(sk.parents):
        if p >= 0:
            assert pos[p] < pos[j]


def test_published_smpl_groups_and_counts():
    sk = get_skeleton("SMPL24")
    assert sk.groups[0] == (0, 3, 6, 9, 12, 15)
    assert sk.joint_names[15] == "head" and sk.parents[15] == 12
    assert (get_skeleton("ntu25").num_joints, get_skeleton("openpose18").num_joints) == (25, 18)
    assert get_skeleton("humanml3d22").num_joints == 22


def test_default_paths_closed_under_the_group_mirror():
    paths = set(DEFAULT_GROUP_PATHS)
    assert len(paths) == 8
    assert {tuple(GROUP_MIRROR[g] for g in p) for p in paths} == paths


def test_invalid_skeletons_are_refused():
    with pytest.raises(ValueError, match="cycle"):
        Skeleton("bad", ("a", "b", "c"), (-1, 2, 1), (0, 1, 2), ((0, 1, 2),))
    with pytest.raises(ValueError, match="miss"):
        Skeleton("bad", ("a", "b", "c"), (-1, 0, 1), (0, 1, 2), ((0, 1),))
    with pytest.raises(KeyError, match="unknown skeleton"):
        get_skeleton("nope")


def test_group_paths_are_the_authors_eight_for_five_groups_else_group_order():
    for skeleton in SKELETONS.values():
        assert skeleton.num_groups == 5 and skeleton.group_paths == DEFAULT_GROUP_PATHS
    three = Skeleton("three", ("a", "b", "c"), (-1, 0, 1), (0, 1, 2), ((0,), (1,), (2,)))
    assert three.group_paths == ((0, 1, 2),)
