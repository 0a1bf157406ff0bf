"""``sm retarget``: motions on rigs built in code (A-pose with rolled rests and an armature scale, VRM 1.0 /
0.x with meaningless names, a tall T-pose), checked by an independent forward kinematics of the written file
(:mod:`retarget_rigs`): bone directions, root path, feet on the floor, no flips, frames and duration."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib
import pytest
from scipy.spatial.transform import Rotation

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.motion.commands.retarget_cli import main as retarget_main
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints
from skeleton_mamba.tasks.motion.synthetic.dance import write_dance
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.retarget_rigs import (
    HUMANOID,
    MIXAMO,
    PAIRS,
    SMPL,
    build_rig,
    read_animated,
    rest_positions,
)

CMU = Path("/work/shared/data/bvh/cmu_01_01.bvh")


@pytest.fixture(scope="module")
def dance(tmp_path_factory) -> Path:
    return write_dance(tmp_path_factory.mktemp("dance"), bpm=120, duration_s=3.0, style="bounce", seed=1)


def _source(path: Path) -> tuple[np.ndarray, list[str], float]:
    clip = load_joints(path)
    return clip.joints, clip.names, clip.fps


def _leg(p: dict[str, np.ndarray]) -> float:
    return (
        sum(
            float(np.linalg.norm(p[s + b] - p[s + a]))
            for s in ("left", "right")
            for a, b in (("UpperLeg", "LowerLeg"), ("LowerLeg", "Foot"))
        )
        / 2
    )


def _check(
    out: Path, rig: Path, positions: dict[str, np.ndarray], motion: Path, source_map: dict[str, str] = SMPL
) -> dict[str, float]:
    """Item 2's numbers for a written glTF rig whose node j + 1 is ``HUMANOID[j]``."""
    src, names, fps = _source(motion)
    sj = {b: names.index(n) for b, n in source_map.items()}
    gltf, times, world, local = read_animated(out)
    frames = len(src)
    node = {b: i + 1 for i, b in enumerate(HUMANOID)}
    pos = world[..., :3, 3]
    # frame count, rate and duration
    assert len(times) == frames
    np.testing.assert_allclose(np.diff(times), 1 / fps, atol=1e-5)
    extras = gltf.animations[0].extras
    assert extras["frames"] == frames and extras["fps"] == fps and extras["duration_s"] == frames / fps
    # the character's mesh and skin are kept
    original = pygltflib.GLTF2().load_binary(str(rig))
    assert len(gltf.meshes) == len(original.meshes) and gltf.skins[0].joints == original.skins[0].joints
    assert gltf.extensions == original.extensions
    # bone directions (the toes of SMPL's foot joint are included)
    errors, source_jump = [], np.zeros(frames - 1)
    for b, t in PAIRS:
        a = pos[:, node[t]] - pos[:, node[b]]
        c = src[:, sj[t]] - src[:, sj[b]]
        if np.linalg.norm(c[0]) < 1e-4:  # CMU's Neck sits on Spine1: no direction
            continue
        cos = np.sum(a * c, -1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(c, axis=-1)
        errors.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
        u = c / np.linalg.norm(c, axis=-1, keepdims=True)
        source_jump = np.maximum(
            source_jump, np.degrees(np.arccos(np.clip(np.sum(u[1:] * u[:-1], -1), -1, 1)))
        )
    errors = np.stack(errors, 1)
    assert errors.mean() <= 5.0 and errors.max() <= 15.0, (errors.mean(), errors.max())
    # the root path, scaled by the leg ratio
    k = _leg(positions) / np.mean([_leg({b: src[f, sj[b]] for b in sj}) for f in range(frames)])
    path = pos[:, node["hips"]] - pos[0, node["hips"]]
    scaled = k * (src[:, sj["hips"]] - src[0, sj["hips"]])
    np.testing.assert_allclose(path[:, [0, 2]], scaled[:, [0, 2]], atol=1e-3)
    lift = np.abs(path[:, 1] - scaled[:, 1]).max()  # the floor correction of the proportions, vertical
    assert lift <= 0.05 * k
    # feet on the floor where the source's are
    feet = []
    for s in ("left", "right"):
        sy = src[:, sj[f"{s}Foot"]][:, 1]
        contact = sy <= sy.min() + 0.02
        ry = pos[:, node[f"{s}Foot"], 1]
        feet.append(np.abs(ry[contact] - k * sy[contact]).max())
    assert max(feet) <= 0.02, feet
    # no flips: frame-to-frame local rotation jumps of the driven bones
    r = local[:, [node[b] for b in HUMANOID]]
    step = Rotation.from_matrix((np.swapaxes(r[:-1], -1, -2) @ r[1:]).reshape(-1, 3, 3)).as_rotvec()
    step = np.degrees(np.linalg.norm(step, axis=-1)).reshape(frames - 1, -1).max(1)
    calm = source_jump < 30.0  # frames where no source bone jumps (CMU 01_01's first frame does)
    assert calm.mean() > 0.99 and step[calm].max() <= 60.0, step[calm].max()
    return {
        "mean": float(errors.mean()),
        "worst": float(errors.max()),
        "feet_m": float(max(feet)),
        "scale": k,
        "lift_m": float(lift),
        "max_step_deg": float(step[calm].max()),
    }


def test_mixamo_a_pose_rolled_rests(dance, tmp_path, capsys):
    names = {b: f"mixamorig:{n}" for b, n in MIXAMO.items()}
    positions = rest_positions(a_pose=True)
    rig = build_rig(tmp_path / "mixamo.glb", names, positions, roll_seed=3, armature_scale=0.01)
    out = tmp_path / "out.glb"
    assert retarget_main([str(dance), "--rig", str(rig), "--out", str(out)]) == 0
    assert "preset mixamo" in capsys.readouterr().out
    print(_check(out, rig, positions, dance))


def test_vrm1_meaningless_names(dance, tmp_path):
    positions = rest_positions(a_pose=True)
    rig = build_rig(
        tmp_path / "avatar.vrm", {b: f"n{i}" for i, b in enumerate(HUMANOID)}, positions, 7, vrm="1"
    )
    out = tmp_path / "avatar_dance.vrm"
    assert retarget_main([str(dance), "--rig", str(rig), "--out", str(out)]) == 0
    print(_check(out, rig, positions, dance))


def test_vrm0_and_tall_t_pose_no_prefix(dance, tmp_path):
    positions = rest_positions(scale=1.25, legs=1.2)
    rig = build_rig(
        tmp_path / "tall.vrm", {b: f"bone{i}" for i, b in enumerate(HUMANOID)}, positions, 11, vrm="0"
    )
    out = tmp_path / "tall_dance.glb"
    assert retarget_main([str(dance), "--rig", str(rig), "--out", str(out)]) == 0
    print(_check(out, rig, positions, dance))
    plain = build_rig(tmp_path / "plain.glb", MIXAMO, positions)
    assert retarget_main([str(dance), "--rig", str(plain), "--out", str(tmp_path / "plain_out.glb")]) == 0
    print(_check(tmp_path / "plain_out.glb", plain, positions, dance))


def test_output_is_valid_gltf(dance, tmp_path):
    from tests.helpers.gltf_reader import assert_khronos_valid

    rig = build_rig(tmp_path / "m.glb", MIXAMO, rest_positions(a_pose=True), roll_seed=3, armature_scale=0.01)
    vrm = build_rig(tmp_path / "v.vrm", MIXAMO, rest_positions(), roll_seed=4, vrm="1")
    for r in (rig, vrm):
        assert retarget_main([str(dance), "--rig", str(r), "--out", str(tmp_path / f"out_{r.stem}.glb")]) == 0
    assert_khronos_valid(rig, tmp_path / "out_m.glb", tmp_path / "out_v.glb")  # skips without the validator


def test_missing_bone_refused(dance, tmp_path):
    positions = {b: p for b, p in rest_positions().items() if "Foot" not in b and "Toes" not in b}
    rig = build_rig(tmp_path / "footless.glb", MIXAMO, positions)
    with pytest.raises(InputError) as err:
        retarget_main([str(dance), "--rig", str(rig), "--out", str(tmp_path / "o.glb")])
    message = str(err.value)
    assert "\n" not in message and "footless.glb" in message
    assert "leftFoot, rightFoot" in message and "mixamo" in message and "--map" in message


def test_explicit_map(dance, tmp_path):
    positions = rest_positions(a_pose=True)
    rig = build_rig(tmp_path / "odd.glb", {b: f"x{i}" for i, b in enumerate(HUMANOID)}, positions, 5)
    bone_map = tmp_path / "map.yaml"
    bone_map.write_text("".join(f"{b}: x{i}\n" for i, b in enumerate(HUMANOID)))
    out = tmp_path / "odd_out.glb"
    assert retarget_main([str(dance), "--rig", str(rig), "--out", str(out), "--map", str(bone_map)]) == 0
    _check(out, rig, positions, dance)
    bone_map.write_text("hips: x0\nelbow: x3\n")
    with pytest.raises(InputError, match="unknown humanoid bones elbow"):
        retarget_main([str(dance), "--rig", str(rig), "--out", str(out), "--map", str(bone_map)])


def test_sm_retarget_end_to_end_with_music(dance, tmp_path, capsys):
    from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

    music = write_music(tmp_path / "song.wav", synthesize_music(120, 4.0))
    rig = build_rig(tmp_path / "c.glb", MIXAMO, rest_positions(a_pose=True), 2)
    out = tmp_path / "c_dance.glb"
    assert sm_main(["retarget", str(dance), "--rig", str(rig), "--out", str(out), "--music", str(music)]) == 0
    assert out.is_file() and out.with_suffix(".wav").is_file()
    assert sm_main(["retarget", str(dance), "--rig", str(rig), "--out", str(tmp_path / "c.bvh")]) == 2
    assert "must be a .glb or .vrm" in capsys.readouterr().err


def test_bad_inputs_one_line(dance, tmp_path, capsys):
    rig = build_rig(tmp_path / "c.glb", MIXAMO, rest_positions())
    (tmp_path / "junk.glb").write_text("not a glb")
    bone_map = tmp_path / "map.yaml"
    bone_map.write_bytes(b"\xff\xfe\x00")
    cases = [
        ([str(dance), "--rig", str(tmp_path / "junk.glb"), "--out", str(tmp_path / "o.glb")], "junk.glb"),
        ([str(dance), "--rig", str(rig), "--out", str(rig)], "its own input"),
        ([str(dance), "--rig", str(rig), "--out", str(tmp_path / "o.glb"), "--map", str(bone_map)],
         "not a text file"),
        ([str(dance), "--rig", str(rig), "--out", str(tmp_path / "nodir" / "o.glb")], "nodir"),
    ]  # fmt: skip
    for argv, expected in cases:
        assert sm_main(["retarget", *argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("sm retarget: error: ") and expected in err, err


@pytest.mark.skipif(not CMU.is_file(), reason=f"no CMU BVH at {CMU} (the shared data folder)")
def test_cmu_walk_onto_vrm(tmp_path):
    """Real mocap (a CMU walk, 120 fps, inches) as the source: feet contacts and root path on a VRM."""
    positions = rest_positions(a_pose=True, legs=0.9)
    rig = build_rig(
        tmp_path / "walker.vrm", {b: f"n{i}" for i, b in enumerate(HUMANOID)}, positions, 9, vrm="1"
    )
    out = tmp_path / "walk.vrm"
    assert retarget_main([str(CMU), "--rig", str(rig), "--out", str(out)]) == 0
    print(_check(out, rig, positions, CMU, dict(MIXAMO, neck="Neck1")))


@pytest.mark.skipif(not CMU.is_file(), reason=f"no CMU BVH at {CMU} (the shared data folder)")
def test_bvh_rig(dance, tmp_path):
    from skeleton_mamba.tasks.motion.formats.bvh import load_bvh
    from skeleton_mamba.tasks.motion.formats.units import choose_scale

    out = tmp_path / "cmu_dance.bvh"
    assert retarget_main([str(dance), "--rig", str(CMU), "--out", str(out)]) == 0
    rig, written = load_bvh(CMU), load_bvh(out)
    src, names, fps = _source(dance)
    assert written.names == rig.names and np.allclose(written.offsets, rig.offsets, atol=1e-5)
    assert written.num_frames == len(src) and written.fps == fps
    # an independent FK of the written BVH (scipy Euler, intrinsic ZXY as the channels say)
    scale = choose_scale(None, None, rig.rest_height()).metres_per_unit
    values = written.values
    col, rot, pos = 0, [], None
    for chs in written.channels:
        if "Xposition" in chs:
            pos = values[:, col : col + 3] * scale
            col += 3
        rot.append(Rotation.from_euler("ZXY", values[:, col : col + 3], degrees=True).as_matrix())
        col += 3
    world_r, world_p = [None] * len(rig.names), [None] * len(rig.names)
    for j, p in enumerate(rig.parents):
        if p < 0:
            world_r[j], world_p[j] = rot[j], pos
        else:
            world_r[j] = world_r[p] @ rot[j]
            world_p[j] = world_p[p] + world_r[p] @ (rig.offsets[j] * scale)
    sj = {b: names.index(n) for b, n in SMPL.items()}
    cmu = {"hips": "Hips", "spine": "Spine", "chest": "Spine1", "neck": "Neck", "head": "Head"}
    for s, S in (("left", "Left"), ("right", "Right")):
        cmu |= {s + "UpperArm": S + "Arm", s + "LowerArm": S + "ForeArm", s + "Hand": S + "Hand",
                s + "UpperLeg": S + "UpLeg", s + "LowerLeg": S + "Leg", s + "Foot": S + "Foot"}  # fmt: skip
    errors = []
    for b, t in PAIRS:
        if b in cmu and t in cmu:
            a = world_p[rig.names.index(cmu[t])] - world_p[rig.names.index(cmu[b])]
            if np.linalg.norm(a[0]) < 1e-6:  # CMU's Neck sits on Spine1: no direction
                continue
            c = src[:, sj[t]] - src[:, sj[b]]
            cos = np.sum(a * c, -1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(c, axis=-1)
            errors.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    errors = np.stack(errors, 1)
    # feet on the floor where the source's are, scaled by the leg-length ratio
    length = [
        np.linalg.norm(rig.offsets[rig.names.index(S + n)]) * scale
        for S in ("Left", "Right")
        for n in ("Leg", "Foot")
    ]
    chain = [(s + "UpperLeg", s + "LowerLeg") for s in ("left", "right")] + [
        (s + "LowerLeg", s + "Foot") for s in ("left", "right")
    ]
    k = sum(length) / sum(np.linalg.norm(src[0, sj[b]] - src[0, sj[a]]) for a, b in chain)
    feet = []
    for s, S in (("left", "Left"), ("right", "Right")):
        sy = src[:, sj[f"{s}Foot"], 1]
        ry = world_p[rig.names.index(f"{S}Foot")][:, 1]
        contact = sy <= sy.min() + 0.02
        feet.append(np.abs(ry[contact] - k * sy[contact]).max())
    print({"mean": float(errors.mean()), "worst": float(errors.max()), "feet_m": float(max(feet))})
    assert errors.mean() <= 5.0 and errors.max() <= 15.0
    assert max(feet) <= 0.02
