"""BVH import (real CMU file, hand-written files) and SMPL-24 export round trips."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix
from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics
from skeleton_mamba.tasks.motion.formats.bvh import BvhError, bvh_to_smpl, load_bvh, save_bvh, smpl_to_bvh
from tests.helpers.motions import HAND_BVH


@pytest.fixture(scope="module")
def cmu(shared_data):
    path = shared_data / "bvh" / "cmu_01_01.bvh"
    if not path.exists():
        pytest.skip(f"{path} not found")
    return path, path.read_text(), load_bvh(path)


def test_cmu_frames_channels_and_root_position(cmu):
    path, text, bvh = cmu
    header, data = text.split("MOTION", 1)
    data_lines = [ln for ln in data.splitlines()[3:] if ln.strip()]
    assert bvh.num_frames == int(re.search(r"Frames:\s*(\d+)", data).group(1)) == len(data_lines) == 2752
    assert bvh.fps == 120.0
    assert len(bvh.names) == len(re.findall(r"^\s*(?:ROOT|JOINT)\s", header, re.M)) == 31
    assert len(bvh.end_sites) == header.count("End Site")
    assert bvh.values.shape[1] == sum(int(n) for n in re.findall(r"CHANNELS\s+(\d+)", header))
    first = np.array(data_lines[0].split(), dtype=float)
    positions = bvh.select_frames([0, -1]).joint_positions()
    np.testing.assert_allclose(positions[0, 0], first[:3])  # Xposition Yposition Zposition of Hips
    last = np.array(data_lines[-1].split(), dtype=float)
    np.testing.assert_allclose(positions[-1, 0], last[:3])


def test_cmu_child_position_by_hand(cmu):
    _, text, bvh = cmu
    header = text.split("MOTION", 1)[0]
    # Hips -> LHipJoint (OFFSET 0 0 0) -> LeftUpLeg; all channels Zrotation Yrotation Xrotation.
    match = re.search(r"JOINT LeftUpLeg\s*\{\s*OFFSET\s+(\S+)\s+(\S+)\s+(\S+)", header)
    up_leg = np.array(match.groups(), dtype=float)
    assert bvh.names[:3] == ["Hips", "LHipJoint", "LeftUpLeg"]
    rest = bvh.values.copy()
    rest[:, 3:] = 0.0  # every rotation channel zero: the rest pose
    rest_pos = dataclasses.replace(bvh, values=rest).select_frames([0]).joint_positions()
    np.testing.assert_allclose(rest_pos[0, 2], bvh.values[0, :3] + up_leg, atol=1e-9)
    # Posed frame 0: LeftUpLeg = root + R_hips R_lhipjoint offset, Euler "ZYX" intrinsic, in degrees.
    r_hips = Rotation.from_euler("ZYX", bvh.values[0, 3:6], degrees=True)
    r_lhip = Rotation.from_euler("ZYX", bvh.values[0, 6:9], degrees=True)
    expected = bvh.values[0, :3] + (r_hips * r_lhip).apply(up_leg)
    np.testing.assert_allclose(bvh.select_frames([0]).joint_positions()[0, 2], expected, atol=1e-9)


def test_cmu_save_load_round_trip(cmu, tmp_path):
    _, _, bvh = cmu
    short = bvh.select_frames(slice(0, 20))
    again = load_bvh(save_bvh(tmp_path / "copy.bvh", short))
    assert again.names == bvh.names and again.parents == bvh.parents and again.channels == bvh.channels
    np.testing.assert_allclose(again.values, short.values, atol=1e-6)
    np.testing.assert_allclose(again.joint_positions(), short.joint_positions(), atol=1e-5)


@pytest.mark.parametrize(
    ("order", "values", "child"),
    [
        ("Xrotation Yrotation Zrotation", "1 2 3 0 0 90 0 0 0", (1, 3, 3)),  # Rz90 (1,0,0) = (0,1,0)
        ("Yrotation Xrotation Zrotation", "0 0 0 90 0 0 0 0 0", (0, 0, -1)),  # Ry90 (1,0,0) = (0,0,-1)
        ("Zrotation Yrotation Xrotation", "0 0 0 0 0 90 0 0 0", (1, 0, 0)),  # Rx90 leaves x
    ],
)
def test_hand_written_file_any_euler_order(tmp_path, order, values, child):
    path = tmp_path / "hand.bvh"
    path.write_text(HAND_BVH.format(order=order, values=values))
    bvh = load_bvh(path)
    assert bvh.fps == 25.0 and bvh.end_sites[1].tolist() == [0, 2, 0]
    np.testing.assert_allclose(bvh.joint_positions()[0, 1], child, atol=1e-12)


def test_malformed_files_name_the_file_and_line(tmp_path):
    path = tmp_path / "bad.bvh"
    path.write_text(HAND_BVH.format(order="Xrotation Yrotation Zrotation", values="1 2 3"))
    with pytest.raises(BvhError, match=r"bad\.bvh:\d+: motion lines have 3 values, channels need 9"):
        load_bvh(path)
    path.write_text(HAND_BVH.format(order="Xrotation Yrotation Wrotation", values="0 " * 9))
    with pytest.raises(BvhError, match=r"bad\.bvh:5: bad CHANNELS"):
        load_bvh(path)
    path.write_text("MOTION\n")
    with pytest.raises(BvhError, match="HIERARCHY"):
        load_bvh(path)


def test_smpl_export_structure_and_round_trip(tmp_path):
    g = torch.Generator().manual_seed(0)
    poses = torch.randn(6, 24, 3, generator=g, dtype=torch.float64) * 0.7
    root = torch.randn(6, 3, generator=g, dtype=torch.float64)
    path = save_bvh(tmp_path / "smpl.bvh", smpl_to_bvh(poses, root, fps=30))
    text = path.read_text()
    lines = [ln.strip() for ln in text.splitlines()]
    assert lines[0] == "HIERARCHY" and lines[1] == "ROOT pelvis"
    assert sum(ln.startswith("JOINT ") for ln in lines) == 23
    assert sum(ln == "End Site" for ln in lines) == 5  # toes, head, hands
    channel_lines = [ln for ln in lines if ln.startswith("CHANNELS")]
    assert channel_lines[0] == "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
    assert all(ln == "CHANNELS 3 Zrotation Xrotation Yrotation" for ln in channel_lines[1:])
    assert "MOTION" in lines and "Frames: 6" in lines and text.count("{") == text.count("}")

    bvh = load_bvh(path)
    assert sorted(bvh.names) == sorted(SMPL24.joint_names) and bvh.fps == 30.0
    # Depth-first file order: pelvis, left leg chain, right leg chain, spine ...
    assert bvh.names[:6] == ["pelvis", "left_hip", "left_knee", "left_ankle", "left_foot", "right_hip"]
    parent_names = {n: bvh.names[p] for n, p in zip(bvh.names, bvh.parents) if p >= 0}
    names = SMPL24.joint_names
    assert parent_names == {names[j]: names[p] for j, p in enumerate(SMPL24.parents) if p >= 0}
    rotations, root_back = bvh_to_smpl(bvh)
    np.testing.assert_allclose(rotations.numpy(), axis_angle_to_matrix(poses).numpy(), atol=1e-5)
    np.testing.assert_allclose(root_back.numpy(), root.numpy(), atol=1e-6)
    expected = smpl_forward_kinematics(axis_angle_to_matrix(poses), root).numpy()
    index = [bvh.names.index(n) for n in SMPL24.joint_names]
    np.testing.assert_allclose(bvh.joint_positions()[:, index], expected, atol=1e-5)
    # Centimetre export: same motion, 100x the numbers.
    cm = load_bvh(save_bvh(tmp_path / "cm.bvh", smpl_to_bvh(poses, root, fps=30, scale=100.0)))
    np.testing.assert_allclose(cm.joint_positions()[:, index] / 100.0, expected, atol=1e-6)
