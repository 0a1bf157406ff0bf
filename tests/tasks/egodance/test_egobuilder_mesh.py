"""EgoAIST++ builder with a user SMPL model (``sm make-ego --smpl-model``): mesh placement and penetration."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.egodance.builder import layout
from skeleton_mamba.tasks.egodance.builder.body_mesh import get_body_model, pose_body
from skeleton_mamba.tasks.egodance.builder.build import BuildConfig, build_window, plan_windows
from skeleton_mamba.tasks.egodance.builder.make_ego_cli import main as make_ego_main
from skeleton_mamba.tasks.egodance.builder.penetration import (
    mesh_penetration_depths,
    mesh_penetration_score,
    signed_distance,
)
from skeleton_mamba.tasks.egodance.builder.placement import place_points, random_placement
from skeleton_mamba.tasks.egodance.builder.procedural_scene import procedural_room
from skeleton_mamba.tasks.motion.formats.motion_file import save_motion
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance
from tests.helpers.smpl import TETRA, rest_joint_positions, write_tiny_smpl_npz
from tests.tasks.egodance.builder_scenes import FLOOR, boxes_scene

WALL = ([1.0, 0.0, -3.0], [1.6, 2.8, 3.0])  # a 60 cm thick wall, its face at x = 1
LEFT_HAND = 22  # the joint farthest along +x in the rest pose


@pytest.fixture
def tiny_model(tmp_path):
    path = write_tiny_smpl_npz(tmp_path / "SMPL_NEUTRAL.npz")
    return path, get_body_model(str(path))


def rest_body(model, root, frames: int = 3):
    poses = torch.zeros(frames, 24, 3, dtype=torch.float64)
    return pose_body(model, poses, torch.tensor(root, dtype=torch.float64).expand(frames, 3))


def test_posed_mesh_is_aligned_to_the_root(tiny_model):
    _, model = tiny_model
    body = rest_body(model, (0.5, 1.0, -0.5))
    # the tiny model's rest joints are the toolkit's rest offsets: its pelvis goes to the root
    expected = rest_joint_positions(pelvis=(0.5, 1.0, -0.5))
    assert body.joints[1] == pytest.approx(expected, abs=1e-12)
    assert body.vertices[1, 4 * LEFT_HAND : 4 * LEFT_HAND + 4] == pytest.approx(expected[LEFT_HAND] + TETRA)
    assert body.anchor[:96] == pytest.approx(np.repeat(np.arange(24), 4)) and body.anchor[96] in (16, 18)


def test_mesh_inside_a_wall_is_rejected_and_a_free_one_passes(tiny_model):
    _, model = tiny_model
    scene = boxes_scene([FLOOR, WALL])
    inside = rest_body(model, (1.3, 1.0, 0.0))
    assert mesh_penetration_score(scene, inside.vertices, inside.joints, inside.anchor) > 2.0
    free = rest_body(model, (-2.5, 1.0, 0.0))
    placement = random_placement(
        free.joints, boxes_scene([FLOOR]), np.random.default_rng(0), 0.0, float(free.vertices[..., 1].min())
    )
    placed_v, placed_j = place_points(free.vertices, placement), place_points(free.joints, placement)
    assert placed_v[..., 1].min() == pytest.approx(0.0, abs=1e-12)  # the lowest vertex on the floor y = 0
    assert mesh_penetration_score(boxes_scene([FLOOR]), placed_v, placed_j, free.anchor) == pytest.approx(0.0)
    assert mesh_penetration_score(scene, free.vertices, free.joints, free.anchor) == pytest.approx(0.0)
    # the hand's outermost vertex 1.5 cm into the wall, the hand joint (2 cm behind it) still outside:
    # found by the joint -> vertex segment ray; S_p = 1.5 cm (vertices have no radius, capsules do)
    reach = rest_body(model, (0.0, 1.0, 0.0))
    shift = 1.015 - reach.vertices[:, 4 * LEFT_HAND : 4 * LEFT_HAND + 4, 0].max()
    reach.vertices[..., 0] += shift
    reach.joints[..., 0] += shift
    assert reach.joints[:, LEFT_HAND, 0] == pytest.approx(0.995)
    assert mesh_penetration_score(scene, reach.vertices, reach.joints, reach.anchor) == pytest.approx(1.5)


def test_screening_matches_the_signed_distance_of_every_vertex(tiny_model):
    """The fast score (Lipschitz bound + one segment ray) against sdf evaluated at every vertex."""
    _, model = tiny_model
    scene = procedural_room(3)
    motion = synthesize_dance(120, 1.0, 10, "arms", 2)
    body = pose_body(model, torch.from_numpy(motion.poses).double(), torch.from_numpy(motion.root_position()))
    rng = np.random.default_rng(5)
    scores = []
    for _ in range(12):
        placement = random_placement(body.joints, scene, rng, 0.0, float(body.vertices[..., 1].min()))
        placement = type(placement)(placement.yaw, tuple(np.add(placement.translation, (0.0, -0.02, 0.0))))
        v, j = place_points(body.vertices, placement), place_points(body.joints, placement)
        fast = mesh_penetration_depths(scene, v, j, body.anchor)
        brute = np.maximum(0.0, -signed_distance(scene, v.reshape(-1, 3))).reshape(v.shape[:2]).max(axis=1)
        assert fast == pytest.approx(brute, abs=1e-12)
        scores.append(brute.max())
    assert min(scores) >= 0.02 - 1e-9  # sunk 2 cm into the 5 cm floor tiles: the soles at least that deep
    # stop_above: a lower bound, still above the threshold
    v, j = place_points(body.vertices, placement), place_points(body.joints, placement)
    early = mesh_penetration_score(scene, v, j, body.anchor, stop_above=2.0, chunk=2)
    assert 2.0 < early <= 100 * scores[-1] + 1e-9


def _motion(tmp_path):
    dance = synthesize_dance(120, 1.0, 10, "sway", 0)
    return save_motion(tmp_path / "m" / "synthetic_sway_120bpm_s0.npz", dance)


def test_build_with_smpl_model_places_and_skips(tmp_path, tiny_model):
    path, model = tiny_model
    motion = _motion(tmp_path)
    floor_file, blocked_file = tmp_path / "floor.ply", tmp_path / "blocked.ply"
    boxes_scene([FLOOR]).mesh.export(floor_file)
    boxes_scene([FLOOR, ([-5.0, 0.0, -5.0], [5.0, 0.5, 5.0])]).mesh.export(blocked_file)
    out = tmp_path / "free"
    args = ["--motion", str(motion), "--scenes", str(floor_file), "--out", str(out), "--fps", "10"]
    args += ["--window", "1", "--width", "8", "--height", "8", "--workers", "1", "--no-progress"]
    assert make_ego_main([*args, "--smpl-model", str(path)]) == 0
    (folder,) = layout.complete_samples(out)
    sample = layout.read_sample(folder, load_frames=False)
    relative = Path(os.path.relpath(path.resolve(), folder.resolve())).as_posix()  # as layout.relative_meta
    assert sample.meta["body"] == {"model": "smpl", "file": str(path.resolve()), "file_relative": relative}
    assert sample.meta["penetration_score"] == pytest.approx(0.0)
    # the saved, placed motion posed with the model: its lowest vertex lies on the floor (y = 0)
    placed = pose_body(
        model, torch.from_numpy(sample.motion.poses).double(), torch.from_numpy(sample.motion.root_position())
    )
    assert placed.vertices[..., 1].min() == pytest.approx(0.0, abs=1e-6)
    assert json.loads((out / "build.json").read_text())["smpl_model"] == str(path.resolve())

    cfg = BuildConfig(
        out=str(tmp_path / "blocked"),
        scenes=str(blocked_file),
        fps=10,
        window_s=1.0,
        width=8,
        height=8,
        max_attempts=2,
        smpl_model=str(path),
        progress=False,
    )
    (task,) = plan_windows(cfg, [motion])
    result = build_window(task, cfg)
    assert result["status"] == "skipped" and result["rejected"] == 2


def test_bad_smpl_model_fails_before_building(tmp_path):
    motion = _motion(tmp_path)
    bad = tmp_path / "model.npz"
    np.savez(bad, v_template=np.zeros((4, 3)))
    with pytest.raises(ValueError, match="model.npz: not an SMPL model file"):
        make_ego_main(["--motion", str(motion), "--out", str(tmp_path / "o"), "--smpl-model", str(bad)])
    assert not (tmp_path / "o").exists()
