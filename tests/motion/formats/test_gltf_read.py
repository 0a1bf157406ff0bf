"""Our .glb exports read back (sm view d.glb, sm render d.glb, sm export d.glb): the joint positions equal the
source's (independent truths: SMPL forward kinematics, the NTU file's keypoints), the frame rate survives, and
malformed files are refused on one line naming the file."""

from __future__ import annotations

import numpy as np
import pygltflib
import pytest
import torch

from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics_axis_angle
from skeleton_mamba.tasks.motion.formats.gltf import from_joints, from_motion_data, write_glb
from skeleton_mamba.tasks.motion.formats.gltf_read import GltfError, read_glb
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints
from skeleton_mamba.tasks.motion.formats.ntu import read_skeleton_file
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.gltf_reader import glb_joint_positions
from tests.helpers.repo import shared_file


def _smpl_motion(frames: int = 20, fps: float = 30.0) -> tuple[MotionData, np.ndarray]:
    rng = np.random.default_rng(1)
    poses = rng.normal(0, 0.4, (frames, 24, 3)).astype(np.float32)
    trans = np.stack([np.linspace(0, 2, frames), np.full(frames, 0.9), np.zeros(frames)], 1)
    trans = trans.astype(np.float32)
    truth = smpl_forward_kinematics_axis_angle(
        torch.from_numpy(poses.astype(np.float64)), torch.from_numpy(trans.astype(np.float64))
    ).numpy()
    return MotionData(fps, poses=poses, trans=trans), truth


def test_rotations_read_back(tmp_path):
    motion, truth = _smpl_motion(fps=25.0)
    path = write_glb(from_motion_data(motion), tmp_path / "d.glb")
    back = read_glb(path)
    assert back.fps == 25.0 and back.num_frames == 20 and back.names[0] == "pelvis"
    assert back.rotations is not None and back.translated[0] and not any(back.translated[1:])
    np.testing.assert_allclose(back.joint_positions(), truth, atol=2e-5, rtol=0)
    # written again, the same file content up to float32 rounding
    again = write_glb(back, tmp_path / "e.glb")
    np.testing.assert_allclose(glb_joint_positions(again)[1], truth, atol=3e-5, rtol=0)


def test_two_bodies_positions_read_back(tmp_path):
    path = shared_file("ntu/S001C001P001R001A001.skeleton")
    clip = load_joints(path)
    glb = tmp_path / "n.glb"
    write_glb(from_joints(clip.joints, None, 30.0, clip.parents, clip.names), glb)
    truth = np.concatenate(list(read_skeleton_file(path).keypoints(max_bodies=2)), axis=1)
    back = load_joints(glb)
    assert back.fps == 30.0 and back.parents == clip.parents
    np.testing.assert_allclose(back.joints, truth, atol=1e-5, rtol=0)


def test_one_frame_keeps_its_rate_from_the_extras(tmp_path):
    motion, _ = _smpl_motion(frames=1, fps=60.0)
    assert read_glb(write_glb(from_motion_data(motion), tmp_path / "one.glb")).fps == 60.0


def test_commands_take_their_own_export(tmp_path, capsys):
    motion, truth = _smpl_motion()
    glb = write_glb(from_motion_data(motion), tmp_path / "d.glb")
    assert sm_main(["view", str(glb), "--out", str(tmp_path / "v.html")]) == 0
    assert sm_main(["export", str(glb), "--out", str(tmp_path / "again.glb")]) == 0
    np.testing.assert_allclose(glb_joint_positions(tmp_path / "again.glb")[1], truth, atol=3e-5, rtol=0)
    assert sm_main(["render", str(glb), "--out", str(tmp_path / "d.gif"), "--quiet"]) == 0
    assert "unsupported" not in capsys.readouterr().err


def _edited(tmp_path, edit) -> str:
    motion, _ = _smpl_motion(frames=4)
    path = write_glb(from_motion_data(motion), tmp_path / "ok.glb")
    gltf = pygltflib.GLTF2().load(str(path))
    edit(gltf)
    bad = tmp_path / "bad.glb"
    gltf.save_binary(str(bad))
    return str(bad)


def _nan_blob(g):
    blob = bytearray(g.binary_blob())
    acc = g.accessors[g.animations[0].samplers[0].output]
    start = g.bufferViews[acc.bufferView].byteOffset
    blob[start : start + 4] = np.float32(np.nan).tobytes()
    g.set_binary_blob(bytes(blob))


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda g: g.skins.clear(), "holds no skin"),
        (lambda g: setattr(g.nodes[1], "children", [*(g.nodes[1].children or []), 0]), "two parents|cycle"),
        (lambda g: setattr(g.accessors[g.animations[0].samplers[0].output], "count", 10**6), "do not fit"),
        (lambda g: setattr(g.animations[0].samplers[0], "interpolation", "CUBICSPLINE"), "CUBICSPLINE"),
        (lambda g: setattr(g.animations[0].channels[0].target, "path", "scale"), "only joints'"),
        (lambda g: setattr(g.nodes[3], "scale", [2, 2, 2]), "matrix or a scale"),
        (lambda g: setattr(g.skins[0], "joints", [0, 99]), "outside"),
        (_nan_blob, "nan"),
    ],
)
def test_malformed_files_are_refused(tmp_path, edit, message):
    with pytest.raises(GltfError, match=message):
        read_glb(_edited(tmp_path, edit))


def test_not_a_glb(tmp_path, capsys):
    (tmp_path / "x.glb").write_text('{"asset": {"version": "2.0"}}')
    with pytest.raises(GltfError, match="no 'glTF' magic"):
        read_glb(tmp_path / "x.glb")
    assert sm_main(["view", str(tmp_path / "x.glb"), "--out", str(tmp_path / "v.html")]) == 2
    assert "x.glb: not a binary glTF" in capsys.readouterr().err
