"""glTF export: the file re-read with pygltflib and a numpy forward kinematics written here (the glTF rule
world = parent @ T(t) R(q), quaternions x y z w) reproduces the source's joint positions at every frame;
the Khronos glTF validator (npm ``gltf-validator``) finds no error when node and the package are present."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib
import pytest
import torch

from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics_axis_angle
from skeleton_mamba.tasks.motion.commands.export_cli import main as export_main
from skeleton_mamba.tasks.motion.formats.bvh import load_bvh, save_bvh, smpl_to_bvh
from skeleton_mamba.tasks.motion.formats.gltf import from_joints, from_motion_data, write_glb
from skeleton_mamba.tasks.motion.formats.humanml3d_features import read_statistics
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints, load_skeleton_motion
from skeleton_mamba.tasks.motion.formats.ntu import read_skeleton_file
from skeleton_mamba.tasks.text2motion.convert_cli import convert_file
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.gltf_reader import accessor, assert_khronos_valid, glb_joint_positions
from tests.helpers.motions import _smpl_motion
from tests.helpers.repo import shared_file

DATA = Path(__file__).resolve().parents[3] / ".." / "shared" / "data"


def test_smpl_rotations_reproduce_joint_positions(tmp_path):
    motion = _smpl_motion()
    out = write_glb(from_motion_data(motion), tmp_path / "smpl.glb")
    names, positions = glb_joint_positions(out)
    poses = torch.from_numpy(motion.poses.astype(np.float64))
    root = torch.from_numpy(motion.root_position().astype(np.float64))
    truth = smpl_forward_kinematics_axis_angle(poses, root).numpy()  # float64 truth
    assert names[:3] == ["pelvis", "left_hip", "right_hip"]
    np.testing.assert_allclose(positions, truth, atol=1e-5, rtol=0)
    gltf = pygltflib.GLTF2().load(str(out))
    paths = {(c.target.node, c.target.path) for c in gltf.animations[0].channels}
    assert (0, "translation") in paths and (5, "rotation") in paths and (5, "translation") not in paths


def test_joint_positions_reproduced_and_npz_reader(tmp_path):
    rng = np.random.default_rng(4)
    joints = rng.normal(0, 0.4, (12, 25, 3)) + [0, 1, 0]
    save_motion(tmp_path / "j.npz", MotionData(25.0, skeleton="ntu25", joints=joints.astype(np.float32)))
    out = write_glb(load_skeleton_motion(tmp_path / "j.npz"), tmp_path / "j.glb")
    _, positions = glb_joint_positions(out)
    np.testing.assert_allclose(positions, joints.astype(np.float32), atol=1e-5, rtol=0)
    np.save(tmp_path / "j.npy", joints)
    _, positions = glb_joint_positions(
        write_glb(load_skeleton_motion(tmp_path / "j.npy"), tmp_path / "k.glb")
    )
    np.testing.assert_allclose(positions, joints, atol=1e-5, rtol=0)


def test_bvh_rotations_reproduce_joint_positions(tmp_path):
    motion = _smpl_motion(10)
    save_bvh(tmp_path / "m.bvh", smpl_to_bvh(motion.poses, motion.root_position(), motion.fps))
    out = write_glb(load_skeleton_motion(tmp_path / "m.bvh"), tmp_path / "m.glb")
    _, positions = glb_joint_positions(out)
    np.testing.assert_allclose(positions, load_bvh(tmp_path / "m.bvh").joint_positions(), atol=1e-5, rtol=0)


@pytest.mark.parametrize("name", ["bvh/cmu_01_01.bvh", "ntu/S001C001P001R001A001.skeleton"])
def test_sample_files(tmp_path, name):
    path = DATA / name
    if not path.is_file():
        pytest.skip(f"sample data {path} absent")
    out = write_glb(load_skeleton_motion(path), tmp_path / "s.glb")
    _, positions = glb_joint_positions(out)
    if path.suffix == ".bvh":  # CMU's unit, 1/0.45 inch, detected from the figure: metres in the file
        truth = load_bvh(path).joint_positions(scale=0.0254 / 0.45)
    else:
        truth = np.concatenate(list(read_skeleton_file(path).keypoints(max_bodies=2)), axis=1)
    assert positions.shape == truth.shape
    np.testing.assert_allclose(positions, truth, atol=1e-5, rtol=0)
    np.testing.assert_allclose(positions, load_joints(path).joints, atol=1e-5, rtol=0)


def _rules_by_rereading(path: Path) -> None:
    """A few of the validator's rules, checked by hand where it cannot run."""
    gltf = pygltflib.GLTF2().load(str(path))
    blob = gltf.binary_blob()
    assert gltf.asset.version == "2.0" and len(blob) == gltf.buffers[0].byteLength
    for acc in gltf.accessors:
        view = gltf.bufferViews[acc.bufferView]
        assert view.byteOffset % 4 == 0 and view.byteOffset + view.byteLength <= len(blob)
    for sampler in gltf.animations[0].samplers:
        acc = gltf.accessors[sampler.input]
        times = accessor(gltf, blob, sampler.input)[:, 0]
        assert acc.min == [times.min()] and acc.max == [times.max()] and np.all(np.diff(times) > 0)
    for ch in gltf.animations[0].channels:
        if ch.target.path == "rotation":
            q = accessor(gltf, blob, gltf.animations[0].samplers[ch.sampler].output)
            np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    joints = gltf.skins[0].joints
    assert len(set(joints)) == len(joints) and gltf.accessors[gltf.skins[0].inverseBindMatrices].count == len(
        joints
    )


def test_khronos_validator(tmp_path):
    motion = _smpl_motion(8)
    files = [write_glb(from_motion_data(motion), tmp_path / "a.glb")]
    files.append(write_glb(from_joints(motion.joint_positions(), "smpl24", 30.0), tmp_path / "b.glb"))
    for f in files:
        _rules_by_rereading(f)
    assert_khronos_valid(*files)


def test_humanml3d_features_export_as_their_joints(tmp_path):
    """A (T, 263) feature file (the dataset's real sample) -> .glb whose FK equals ``sm convert``'s joints."""
    features = shared_file("humanml3d/new_joint_vecs/012314.npy")
    assert export_main([str(features), "--out", str(tmp_path / "h.glb")]) == 0
    names, positions = glb_joint_positions(tmp_path / "h.glb")
    joints = np.load(convert_file(features, tmp_path / "joints.npy"))
    assert names[0] == "pelvis" and positions.shape == joints.shape == (len(np.load(features)), 22, 3)
    np.testing.assert_allclose(positions, joints, atol=1e-5, rtol=0)
    _rules_by_rereading(tmp_path / "h.glb")


@pytest.mark.parametrize(
    "bad, message",
    [
        (np.ones((5, 263), np.complex64), "'features' must hold real numbers, got dtype complex64"),
        (
            np.full((5, 263), 1e30, np.float32),
            "features: 1e+30 at frame 0, column 0 (0-based) is beyond the plausible 10000",
        ),
        (np.ones((5, 263), bool), "'features' must hold real numbers, got dtype bool"),
    ],
)
def test_hostile_humanml3d_features_refused(tmp_path, capsys, bad, message):
    np.save(tmp_path / "f.npy", bad)
    assert sm_main(["export", str(tmp_path / "f.npy"), "--out", str(tmp_path / "f.glb")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sm export: error: ") and str(tmp_path / "f.npy") in err and message in err, err
    assert len(err.splitlines()) == 1 and not (tmp_path / "f.glb").exists()


def test_humanml3d_statistics_of_absurd_size_refused(tmp_path):
    np.save(tmp_path / "Mean.npy", np.zeros(263, np.float32))
    np.save(tmp_path / "Std.npy", np.full(263, 1e30, np.float32))
    with pytest.raises(
        ValueError, match=r"Std\.npy: Std: 1e\+30 at column 0 \(0-based\) is beyond the plausible 10000"
    ):
        read_statistics(tmp_path)
