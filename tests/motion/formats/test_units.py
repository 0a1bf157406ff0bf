"""Every reader returns metres: a BVH's unit is detected from its figure, or given (--units, --scale), and the
scale is stated (stderr, the glTF's asset.extras, the viewer page). Truth: SMPL forward kinematics in metres
of the same poses, computed independently of the BVH path."""

from __future__ import annotations

import json

import numpy as np
import pygltflib
import pytest
import torch

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics_axis_angle
from skeleton_mamba.tasks.motion.formats.bvh import save_bvh, smpl_to_bvh
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints, load_skeleton_motion
from skeleton_mamba.tasks.motion.formats.units import CMU_UNIT_M, choose_scale, detect_scale
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.repo import shared_file


def _smpl(frames: int = 12):
    rng = np.random.default_rng(0)
    poses = rng.normal(0, 0.3, (frames, 24, 3))
    root = np.stack([np.linspace(0, 1, frames), np.full(frames, 0.95), np.zeros(frames)], axis=1)
    truth = smpl_forward_kinematics_axis_angle(torch.from_numpy(poses), torch.from_numpy(root)).numpy()
    return poses, root, truth


@pytest.mark.parametrize(
    ("unit", "per_metre", "detected"),
    [("m", 1.0, "m"), ("cm", 100.0, "cm"), ("in", 1 / 0.0254, "in"), ("cmu", 1 / CMU_UNIT_M, "CMU units")],
)
def test_bvh_unit_detected_from_the_figure(tmp_path, unit, per_metre, detected):
    poses, root, truth = _smpl()
    path = save_bvh(tmp_path / f"{unit}.bvh", smpl_to_bvh(poses, root, 30.0, scale=per_metre))
    clip = load_joints(path)
    truth = truth[:, [SMPL24.index(n) for n in clip.names]]  # the BVH lists the joints depth-first
    np.testing.assert_allclose(clip.joints, truth, atol=1e-4, rtol=0)
    assert clip.scale.metres_per_unit == pytest.approx(1 / per_metre)
    assert f"unit detected: {detected}" in clip.scale.note
    glb = load_skeleton_motion(path)
    np.testing.assert_allclose(glb.joint_positions(), truth, atol=1e-4, rtol=0)


def test_given_units_and_scale_replace_detection(tmp_path):
    poses, root, truth = _smpl()
    path = save_bvh(tmp_path / "cm.bvh", smpl_to_bvh(poses, root, 30.0, scale=100.0))
    truth = truth[:, [SMPL24.index(n) for n in load_joints(path).names]]
    np.testing.assert_allclose(load_joints(path, units="m").joints, truth * 100, atol=1e-3, rtol=0)
    np.testing.assert_allclose(load_joints(path, scale=0.02).joints, truth * 2, atol=1e-4, rtol=0)
    np.save(tmp_path / "j.npy", truth)  # joints .npy are metres by the format; --units applies to any file
    np.testing.assert_allclose(load_joints(tmp_path / "j.npy", units="cm").joints, truth / 100, atol=1e-9)
    assert load_joints(tmp_path / "j.npy").scale.note == "metres, by the file format"
    with pytest.raises(ValueError, match="not both"):
        choose_scale("cm", 0.01)
    with pytest.raises(ValueError, match="metres per file unit"):
        choose_scale(None, -1.0)


def test_unknown_unit_scaled_to_a_typical_figure_and_said():
    tiny = detect_scale(0.03)  # 0.03 m, 0.3 mm ... no unit makes a person of it
    assert tiny.metres_per_unit == pytest.approx(1.7 / 0.03)
    assert "unknown unit" in tiny.note and "--units" in tiny.note
    assert "no height" in detect_scale(0.0).note


def test_cmu_sample_in_metres_and_stated_everywhere(tmp_path, capsys):
    path = shared_file("bvh/cmu_01_01.bvh")
    clip = load_joints(path)
    hips = clip.joints[:, 0, 1]  # 14.5 to 22.8 file units
    assert 0.75 < hips.min() < hips.max() < 1.35
    out = tmp_path / "d.glb"
    assert sm_main(["export", str(path), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "cmu_01_01.bvh: lengths x 0.0564444 to metres (unit detected: CMU units (1/0.45 in)" in err
    extras = pygltflib.GLTF2().load(str(out)).asset.extras
    assert extras["units"] == "metres" and extras["metres_per_source_unit"] == pytest.approx(CMU_UNIT_M)
    assert extras["fps"] == 120.0
    html = tmp_path / "v.html"
    assert sm_main(["view", str(path), "--out", str(html)]) == 0
    data = html.read_text().split('<script id="sm-data" type="application/json">')[1].split("</script>")[0]
    assert json.loads(data)["notes"] == [f"cmu_01_01: {clip.scale.describe()}"]
    with pytest.raises(SystemExit, match="2"):  # argparse: not allowed together
        sm_main(["export", str(path), "--units", "cm", "--scale", "2", "--out", str(out)])
