"""EgoAIST++ builder (``sm make-ego``): scenes, placement, penetration, camera, renderer, layout, resume."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import torch
import trimesh

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.egodance.builder import layout
from skeleton_mamba.tasks.egodance.builder.build import (
    BuildConfig,
    build_window,
    get_scene,
    plan_windows,
    run_build,
    scene_keys,
)
from skeleton_mamba.tasks.egodance.builder.camera import head_camera, intrinsics
from skeleton_mamba.tasks.egodance.builder.make_ego_cli import main as make_ego_main
from skeleton_mamba.tasks.egodance.builder.penetration import FOOT_RADIUS, penetration_score, signed_distance
from skeleton_mamba.tasks.egodance.builder.placement import place_points, random_placement
from skeleton_mamba.tasks.egodance.builder.procedural_scene import procedural_room
from skeleton_mamba.tasks.egodance.builder.raycast import render_view
from skeleton_mamba.tasks.egodance.builder.scene import load_scene, make_scene
from skeleton_mamba.tasks.motion.body.kinematics import forward_kinematics
from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics_axis_angle, smpl_rest_offsets
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance
from tests.tasks.egodance.builder_scenes import FEET, FLOOR, boxes_scene, rest_joints


# ---------------------------------------------------------------- scenes
def test_real_room_floor_and_up_axis(shared_data):
    path = shared_data / "scenes" / "simple_room.glb"
    scene = load_scene(path, up_axis="z")
    # independent: the largest part of the glTF (the floor slab) read with trimesh, its top in z
    raw = trimesh.load(path)
    tops = []
    for node in raw.graph.nodes_geometry:
        transform, name = raw.graph[node]
        part = raw.geometry[name].copy()
        part.apply_transform(transform)
        tops.append((part.area, part.bounds[1, 2]))
    floor_top = max(tops)[1]
    # the slab is tilted by ~3e-6 rad in the file: its top corners differ by a few micrometres
    assert scene.floor_height == pytest.approx(floor_top, abs=1e-5)
    # z-up -> y-up: the scene's height range becomes the y range
    assert scene.mesh.bounds[:, 1] == pytest.approx(raw.bounds[:, 2], abs=1e-6)
    assert scene.mesh.bounds[:, 2] == pytest.approx(-raw.bounds[::-1, 1], abs=1e-6)


def test_load_scene_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="scene file not found"):
        load_scene(tmp_path / "missing.glb")
    bad = tmp_path / "broken.ply"
    bad.write_text("not a mesh")
    with pytest.raises(ValueError, match="broken.ply"):
        load_scene(bad)
    with pytest.raises(ValueError, match="up axis"):
        load_scene(bad, up_axis="w")


def test_procedural_room_is_deterministic_and_furnished():
    a, b, c = procedural_room(7), procedural_room(7), procedural_room(8)
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices)
    assert not np.array_equal(a.mesh.vertices, c.mesh.vertices) or a.source != c.source
    assert a.floor_height == pytest.approx(0.0, abs=1e-9)  # tiles' tops are at y = 0 by construction
    colors = np.unique(a.mesh.visual.vertex_colors[:, :3], axis=0)
    assert len(colors) >= 6  # two tile colours, wall bands, ceiling, furniture
    # something stands on the floor besides the walls: a triangle centre above 0.3 m inside the room
    inner = (
        np.abs(a.mesh.triangles_center[:, [0, 2]]).max(axis=1) < np.abs(a.mesh.bounds[:, [0, 2]]).min() - 0.2
    )
    assert (a.mesh.triangles_center[inner, 1] > 0.3).any()


# ---------------------------------------------------------------- placement and penetration
def test_placement_keeps_lowest_foot_on_floor():
    scene = boxes_scene([FLOOR, ([2.0, 0.0, 2.0], [3.0, 1.0, 3.0])])
    joints = smpl_forward_kinematics_axis_angle(
        torch.from_numpy(synthesize_dance(110, 2.0, 30, "bounce", 3).poses).double(),
        torch.tensor([0.3, 1.4, -0.2], dtype=torch.float64).expand(60, 3),  # deliberately floating
    ).numpy()
    rng = np.random.default_rng(0)
    for _ in range(5):
        placement = random_placement(joints, scene, rng)
        placed = place_points(joints, placement)
        assert placed[:, FEET, 1].min() == pytest.approx(FOOT_RADIUS, abs=1e-9)  # floor at y = 0
        # rigid: bone lengths and heights above the lowest foot are kept
        assert np.linalg.norm(placed[:, 4] - placed[:, 1], axis=-1) == pytest.approx(
            np.linalg.norm(joints[:, 4] - joints[:, 1], axis=-1)
        )
        # the mean root lands on the floor area
        centre = placed[:, 0].mean(axis=0)
        assert -5 <= centre[0] <= 5 and -5 <= centre[2] <= 5


def test_signed_distance_against_box_faces():
    scene = boxes_scene([FLOOR, ([0.0, 0.0, 0.0], [1.0, 2.0, 1.0])])
    points = np.array([[1.3, 1.0, 0.5], [0.5, 1.0, 0.9], [0.5, 2.25, 0.5], [-2.0, 0.5, -2.0]])
    # hand values: 0.3 outside the +x face, 0.1 inside behind the +z face, 0.25 above the top, 0.5 above floor
    assert signed_distance(scene, points) == pytest.approx([0.3, -0.1, 0.25, 0.5], abs=1e-9)


def test_body_inside_wall_scores_above_threshold_and_is_rejected(tmp_path):
    wall = ([1.0, 0.0, -3.0], [1.6, 2.8, 3.0])  # a 60 cm thick wall
    scene = boxes_scene([FLOOR, wall])
    inside = rest_joints(root=(1.3, 0.93, 0.0))
    free = rest_joints(root=(-2.5, 0.93, 0.0))
    free[..., 1] += FOOT_RADIUS - free[:, FEET, 1].min()  # feet touching the floor
    assert penetration_score(scene, inside) > 2.0
    assert penetration_score(scene, free) == pytest.approx(0.0, abs=1e-6)
    # an arm reaching 5 cm into the wall: depth = (hand sphere radius + 5 cm) -> S_p in cm
    reach = rest_joints(root=(0.0, 1.0, 0.0))
    reach[..., 0] += 1.0 + 0.05 - reach[:, 22, 0].max()  # left hand (joint 22, +x) 5 cm past x = 1.0
    assert penetration_score(scene, reach) == pytest.approx(100 * (0.04 + 0.05), abs=1e-6)

    # a scene whose whole floor is covered by a block: every placement collides -> skipped, logged
    blocked = boxes_scene([FLOOR, ([-5.0, 0.0, -5.0], [5.0, 0.5, 5.0])], name="blocked")
    scene_file = tmp_path / "blocked.ply"
    blocked.mesh.export(scene_file)
    motion = save_motion(tmp_path / "m" / "dance.npz", synthesize_dance(120, 1.0, 10, "sway", 0))
    cfg = BuildConfig(
        out=str(tmp_path / "out"),
        scenes=str(scene_file),
        fps=10,
        window_s=1.0,
        width=8,
        height=8,
        max_attempts=3,
        progress=False,
        workers=1,
    )
    (task,) = plan_windows(cfg, [motion])
    result = build_window(task, cfg)
    assert result["status"] == "skipped" and result["rejected"] == 3
    record = json.loads((tmp_path / "out" / "skipped" / f"{task.sample_id}.json").read_text())
    assert len(record["scores"]) == 3 and min(record["scores"]) > 2.0
    assert "no placement with S_p <= 2.0" in record["reason"]
    assert not layout.sample_dir(cfg.out, task.sample_id).exists()


# ---------------------------------------------------------------- renderer and camera
def test_depth_and_colour_of_a_plane_at_known_distance():
    scene = boxes_scene([FLOOR])
    width, height = 40, 30
    K = intrinsics(width, height, 70.0)
    down = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # optical axis -y, det +1
    assert np.linalg.det(down) == pytest.approx(1.0)
    rgb, depth = render_view(scene, np.array([0.2, 2.5, -0.3]), down, K, width, height, ambient=0.3)
    assert depth == pytest.approx(np.full((height, width), 2.5), abs=1e-5)  # z-depth of the plane y = 0
    # shading: 0.3 + 0.7 cos(angle between ray and normal), cos = 1 / |(x, y, 1)| at pixel centres
    u, v = 3, 27
    x, y = (u + 0.5 - width / 2) / K[0, 0], (v + 0.5 - height / 2) / K[1, 1]
    expected = 200 * (0.3 + 0.7 / np.sqrt(x * x + y * y + 1))
    assert rgb[v, u] == pytest.approx([expected] * 3, abs=1.0)
    # looking up at nothing: depth 0, background colour
    up = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # optical axis +y
    rgb, depth = render_view(scene, np.array([0.0, 2.5, 0.0]), up, K, width, height, background=(1, 2, 3))
    assert (depth == 0).all() and (rgb == [1, 2, 3]).all()


def test_vertex_colours_are_interpolated_at_the_hit():
    # one big floor triangle with a red, a green and a blue corner (normal +y), seen from 1.5 m above
    corners = np.array([[-4.0, 0.0, -4.0], [0.0, 0.0, 4.0], [4.0, 0.0, -4.0]])
    colors = np.array([[240, 0, 0], [0, 240, 0], [0, 0, 240]], dtype=np.uint8)
    scene = make_scene("tri", corners, np.array([[0, 1, 2]]), colors)
    assert scene.mesh.face_normals[0] == pytest.approx([0.0, 1.0, 0.0])
    width, height, position = 24, 20, np.array([0.3, 1.5, -0.2])
    K = intrinsics(width, height, 60.0)
    down = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    rgb, depth = render_view(scene, position, down, K, width, height, ambient=0.3)
    for u, v in [(0, 0), (5, 17), (12, 10), (23, 19)]:
        ray = down @ np.array([(u + 0.5 - width / 2) / K[0, 0], (v + 0.5 - height / 2) / K[1, 1], 1.0])
        hit = position + ray * (position[1] / -ray[1])  # where the ray meets y = 0
        # barycentric weights of the hit: solve hit = sum_i w_i corner_i with sum_i w_i = 1
        w = np.linalg.solve(np.vstack([corners[:, [0, 2]].T, np.ones(3)]), [hit[0], hit[2], 1.0])
        shade = 0.3 + 0.7 * abs(ray[1]) / np.linalg.norm(ray)
        assert rgb[v, u] == pytest.approx(w @ colors * shade, abs=1.0)
        assert depth[v, u] == pytest.approx(1.5, abs=1e-5)


def _random_rays(n: int = 400):
    rng = np.random.default_rng(0)
    origins = rng.uniform([-1.5, 0.3, -1.5], [1.5, 2.0, 1.5], (n, 3))
    return origins, rng.normal(size=(n, 3)) * rng.uniform(0.2, 3.0, (n, 1))  # not normalised


def test_ray_caster_hits_lie_on_the_hit_triangles():
    pytest.importorskip("embreex", reason="the all-hits reference below is trimesh's embree intersector")
    scene = procedural_room(2)
    origins, directions = _random_rays()
    hits = scene.caster.first_hits(origins, directions)
    assert (hits.tri >= 0).all()  # a closed room: every ray hits
    point = origins + hits.t[:, None] * directions  # t is in units of the (unnormalised) direction
    tri = scene.mesh.triangles[hits.tri]
    plane = np.einsum("ij,ij->i", point - tri[:, 0], scene.mesh.face_normals[hits.tri])
    assert np.abs(plane).max() < 1e-4
    # (u, v) are the barycentric coordinates of corners b and c (trimesh computes them independently)
    bary = trimesh.triangles.points_to_barycentric(tri, point)
    assert np.stack([hits.u, hits.v], 1) == pytest.approx(bary[:, 1:], abs=1e-3)
    # the first hit: nothing on the mesh is closer along the ray (trimesh's own ray test, all hits)
    locations, index_ray, _ = trimesh.ray.ray_pyembree.RayMeshIntersector(scene.mesh).intersects_location(
        origins, directions, multiple_hits=True
    )
    nearest = np.full(len(origins), np.inf)
    np.minimum.at(nearest, index_ray, np.linalg.norm(locations - origins[index_ray], axis=1))
    assert hits.t * np.linalg.norm(directions, axis=1) == pytest.approx(nearest, abs=1e-4)


def _spy_trimesh_calls(monkeypatch, caster) -> list[int]:
    """Records the number of rays of every call the caster makes to trimesh's intersector."""
    sizes: list[int] = []
    original = caster._trimesh.intersects_id

    def spy(origins, directions, **kwargs):
        sizes.append(len(directions))
        return original(origins, directions, **kwargs)

    monkeypatch.setattr(caster._trimesh, "intersects_id", spy)
    return sizes


def test_trimesh_ray_caster_is_chunked_and_matches_one_call(monkeypatch):
    from skeleton_mamba.tasks.egodance.builder.ray_caster import RayCaster

    pytest.importorskip("rtree", reason="trimesh's numpy ray caster (the fallback) needs rtree")
    scene = procedural_room(2)
    origins, directions = _random_rays()
    faces = len(scene.mesh.faces)
    chunked = RayCaster(scene.mesh.vertices, scene.mesh.faces, backend="trimesh", pair_budget=37 * faces)
    assert chunked.chunk_rays == 37
    sizes = _spy_trimesh_calls(monkeypatch, chunked)
    hits = chunked.first_hits(origins, directions)
    # the work is split: no call holds more than chunk_rays rays (at most pair_budget candidate pairs)
    assert sizes == [37] * (len(origins) // 37) + [len(origins) % 37]
    whole = RayCaster(scene.mesh.vertices, scene.mesh.faces, backend="trimesh", pair_budget=10**9)
    once = whole.first_hits(origins, directions)
    assert (hits.tri >= 0).all()  # a closed room
    for name in ("tri", "t", "u", "v"):
        np.testing.assert_array_equal(getattr(hits, name), getattr(once, name))
    # the hits lie on their triangles
    point = origins + hits.t[:, None] * directions
    plane = np.einsum(
        "ij,ij->i", point - scene.mesh.triangles[hits.tri][:, 0], scene.mesh.face_normals[hits.tri]
    )
    assert np.abs(plane).max() < 1e-4


def test_embree_and_trimesh_ray_casters_agree(monkeypatch):
    from skeleton_mamba.tasks.egodance.builder.ray_caster import RayCaster

    pytest.importorskip("rtree", reason="trimesh's numpy ray caster (the fallback) needs rtree")
    pytest.importorskip("embreex", reason="embreex is not installed: nothing to compare the fallback with")
    scene = procedural_room(2)
    origins, directions = _random_rays()
    embree = RayCaster(scene.mesh.vertices, scene.mesh.faces, backend="embree").first_hits(
        origins, directions
    )
    monkeypatch.setenv("SKELETON_MAMBA_RAY_CASTER", "trimesh")  # the switch `sm make-ego` users have
    caster = RayCaster(scene.mesh.vertices, scene.mesh.faces, pair_budget=50 * len(scene.mesh.faces))
    assert caster.backend == "trimesh"
    sizes = _spy_trimesh_calls(monkeypatch, caster)
    fallback = caster.first_hits(origins, directions)
    assert len(sizes) == 8 and max(sizes) == 50
    same = embree.tri == fallback.tri
    assert same.mean() > 0.98
    for name in ("t", "u", "v"):
        assert getattr(embree, name)[same] == pytest.approx(getattr(fallback, name)[same], abs=2e-4)
    # where the triangles differ (a ray through a shared edge), the distance is the same
    assert embree.t == pytest.approx(fallback.t, abs=2e-4)


def test_ray_caster_choice(monkeypatch):
    from skeleton_mamba.tasks.egodance.builder import ray_caster

    monkeypatch.setenv(ray_caster.RAY_CASTER_ENV, "trimesh")
    assert ray_caster.resolve_backend() == "trimesh"
    assert ray_caster.resolve_backend("auto") == ("embree" if ray_caster.HAS_EMBREE else "trimesh")
    monkeypatch.setenv(ray_caster.RAY_CASTER_ENV, "optix")
    with pytest.raises(ValueError, match="optix.*auto, embree or trimesh"):
        ray_caster.resolve_backend()
    monkeypatch.setattr(ray_caster, "HAS_EMBREE", False)
    with pytest.raises(ImportError, match="embreex is not installed"):
        ray_caster.resolve_backend("embree")


def test_head_camera_moves_with_head():
    offsets = smpl_rest_offsets(torch.float64)
    rot = torch.eye(3, dtype=torch.float64).repeat(2, 24, 1, 1)
    # frame 1: root moved by (0.5, 0, 1) and the neck (joint 12) turned +90 degrees about y
    rot[1, 12] = torch.tensor([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]], dtype=torch.float64)
    root = torch.tensor([[0.0, 0.9, 0.0], [0.5, 0.9, 1.0]], dtype=torch.float64)
    joints, world = forward_kinematics(rot, root, offsets, SMPL24.parents)
    joints, world = joints.numpy(), world.numpy()
    K = intrinsics(16, 16, 90.0)
    cam = head_camera(joints[:, 15], world[:, 15], K, 16, 16, forward_offset=0.1, up_offset=0.06)
    # frame 0 (rest pose): eyes 6 cm above and 10 cm in front (+z) of the head, looking along +z
    assert cam.positions[0] == pytest.approx(joints[0, 15] + [0.0, 0.06, 0.1])
    assert cam.rotations[0][:, 2] == pytest.approx([0.0, 0.0, 1.0])
    assert cam.rotations[0][:, 0] == pytest.approx([-1.0, 0.0, 0.0])  # image right = the body's right
    assert cam.rotations[0][:, 1] == pytest.approx([0.0, -1.0, 0.0])  # image down
    # frame 1: the head turned to +x, so the eyes are 10 cm along +x and the camera looks along +x
    assert cam.positions[1] == pytest.approx(joints[1, 15] + [0.1, 0.06, 0.0])
    assert cam.rotations[1][:, 2] == pytest.approx([1.0, 0.0, 0.0])
    # the head joint itself moved with the root translation
    assert joints[1, 12] - joints[0, 12] == pytest.approx([0.5, 0.0, 1.0])


# ---------------------------------------------------------------- full builds
def _write_motion(tmp_path, seconds=2.0, fps=10.0, style="bounce"):
    motion = synthesize_dance(120, seconds, fps, style, 1)
    path = save_motion(tmp_path / "motions" / f"synthetic_{style}_120bpm_s1.npz", motion)
    (tmp_path / "motions" / f"synthetic_{style}_120bpm_s1.wav").write_bytes(b"")  # sidecar music reference
    return path


def test_build_on_real_room_writes_documented_layout(tmp_path, shared_data):
    room = shared_data / "scenes" / "simple_room.glb"
    motion = _write_motion(tmp_path)
    out = tmp_path / "ego"
    code = make_ego_main(
        [
            "--motion",
            str(motion),
            "--scenes",
            str(room),
            "--up-axis",
            "z",
            "--out",
            str(out),
            "--fps",
            "10",
            "--window",
            "1",
            "--width",
            "32",
            "--height",
            "24",
            "--frames",
            "png",
            "--workers",
            "1",
            "--no-progress",
        ]
    )
    assert code == 0
    samples = layout.complete_samples(out)
    assert [s.name for s in samples] == [
        "synthetic_bounce_120bpm_s1__w000",
        "synthetic_bounce_120bpm_s1__w001",
    ]
    folder = samples[1]
    names = {p.name for p in folder.iterdir()}
    assert names == {"meta.json", "motion.npz", "camera.npz", "rgb", "depth.npz", "COMPLETE"}
    assert len(list((folder / "rgb").glob("*.png"))) == 10
    sample = layout.read_sample(folder)
    meta = sample.meta
    assert meta["synthetic"] is True and meta["sample_id"] == folder.name
    assert meta["motion"]["start_frame"] == 10 and meta["motion"]["num_frames"] == 10
    assert meta["music"]["path"].endswith("synthetic_bounce_120bpm_s1.wav")
    assert (meta["music"]["start_s"], meta["music"]["end_s"]) == (1.0, 2.0)
    assert meta["penetration_score"] <= meta["threshold"] == 2.0
    assert sample.rgb.shape == (10, 24, 32, 3) and sample.depth.shape == (10, 24, 32)
    assert sample.camera["positions"].shape == (10, 3) and sample.camera["K"][0, 2] == 16.0
    rotations = sample.camera["rotations"].astype(np.float64)
    assert np.einsum("tij,tik->tjk", rotations, rotations) == pytest.approx(
        np.tile(np.eye(3), (10, 1, 1)), abs=1e-5
    )
    # the placed motion: FK of the saved SMPL parameters gives the saved joints (placement applied to both)
    joints = smpl_forward_kinematics_axis_angle(
        torch.from_numpy(sample.motion.poses).double(),
        torch.from_numpy(sample.motion.root_position()).double(),
    ).numpy()
    assert joints == pytest.approx(sample.motion.joints, abs=1e-4)
    floor = meta["scene"]["floor_height"]
    assert joints[:, FEET, 1].min() >= floor + FOOT_RADIUS - 1e-4
    # the camera sits at the eye offset from the placed head joint in every frame
    eye = np.linalg.norm(sample.camera["positions"] - joints[:, 15], axis=1)
    assert eye == pytest.approx(np.full(10, np.hypot(0.06, 0.10)), abs=1e-4)
    # a head-height camera in the room sees surfaces at plausible depths
    assert (sample.depth > 0).mean() > 0.1 and sample.depth.max() < 16.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["placed"] == 2 and summary["skipped"] == 0 and summary["complete"] == 2


def test_interrupted_build_resumes(tmp_path):
    motion = _write_motion(tmp_path, seconds=3.0, style="arms")
    out = tmp_path / "ego"
    cfg = BuildConfig(
        out=str(out),
        scenes="procedural",
        num_rooms=2,
        fps=10,
        window_s=1.0,
        width=16,
        height=16,
        progress=False,
        workers=2,
    )
    first = run_build(cfg, motion)
    assert (first.placed, first.complete) == (3, 3)
    a, b, c = layout.complete_samples(out)
    # simulate an interruption: A lost its marker (half written), a temp folder was left, C untouched
    (a / layout.COMPLETE).unlink()
    leftover = out / layout.SAMPLES / f"{layout.TMP_PREFIX}{b.name}-99999"
    leftover.mkdir()
    (leftover / "motion.npz").write_bytes(b"partial")
    assert [p.name for p in layout.complete_samples(out)] == [b.name, c.name]
    with pytest.raises(ValueError, match="not a complete sample"):
        layout.read_sample(a)
    stamp = os.stat(c / "meta.json").st_mtime_ns
    second = run_build(cfg, motion)
    assert (second.placed, second.already_complete, second.complete) == (1, 2, 3)
    assert not leftover.exists()
    assert layout.is_complete(a) and layout.read_sample(a, load_frames=False).meta["sample_id"] == a.name
    assert os.stat(c / "meta.json").st_mtime_ns == stamp  # complete samples are not rebuilt
    # a resume with other data settings is refused
    with pytest.raises(ValueError, match="other settings"):
        run_build(
            BuildConfig(
                out=str(out),
                scenes="procedural",
                num_rooms=2,
                fps=10,
                window_s=1.0,
                width=32,
                height=16,
                progress=False,
            ),
            motion,
        )


def test_motion_without_smpl_parameters_is_refused(tmp_path):
    joints_only = MotionData(fps=30, skeleton="smpl24", joints=rest_joints(5).astype(np.float32))
    path = save_motion(tmp_path / "joints.npz", joints_only)
    with pytest.raises(ValueError, match="joints.npz: the builder needs SMPL parameters"):
        plan_windows(BuildConfig(out=str(tmp_path / "o")), [path])


def test_scene_folder_pattern_picks_replica_meshes(tmp_path):
    scene = boxes_scene([FLOOR])
    for rel in ("room_0/mesh.ply", "room_0/habitat/mesh_semantic.ply", "office_1/mesh.ply"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        scene.mesh.export(tmp_path / rel)
    everything = scene_keys(BuildConfig(out="o", scenes=str(tmp_path)))
    assert len(everything) == 3
    keys = scene_keys(BuildConfig(out="o", scenes=str(tmp_path), scene_pattern="*/mesh.ply"))
    assert keys == [str(tmp_path / "office_1" / "mesh.ply"), str(tmp_path / "room_0" / "mesh.ply")]
    assert get_scene(keys[1], "y").name == "room_0"
    with pytest.raises(FileNotFoundError, match=r"\*/nothing.glb"):
        scene_keys(BuildConfig(out="o", scenes=str(tmp_path), scene_pattern="*/nothing.glb"))


def test_stopping_the_pool_ends_its_workers_without_running_the_queued_windows():
    """``_stop_pool`` (Ctrl-C or a failed window) terminates the running workers and cancels the queue."""
    import multiprocessing
    import time
    from concurrent.futures import ProcessPoolExecutor

    from skeleton_mamba.tasks.egodance.builder import build

    others = set(multiprocessing.active_children())
    context = build._pool_context()
    pool = ProcessPoolExecutor(max_workers=2, mp_context=context, initializer=build._init_worker)
    futures = [pool.submit(time.sleep, 60) for _ in range(6)]  # 2 running, 1 in the call queue, 3 waiting
    workers = [p for p in multiprocessing.active_children() if p not in others]
    assert len(workers) == 2 and all(p.is_alive() for p in workers)
    start = time.monotonic()
    build._stop_pool(pool, others)
    assert time.monotonic() - start < 30  # not the 2 x 60 s of sleeping windows
    assert not any(p.is_alive() for p in workers)
    assert futures[-1].cancelled()
