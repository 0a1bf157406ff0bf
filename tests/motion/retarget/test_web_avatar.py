"""``sm export-web --rig``: the page's dancer drives the user's character (rigs built in code,
:mod:`retarget_rigs`).

A VRM 1.0 and a VRM 0.x, each with meaningless node names, are drawn by three-vrm's loader. The per-frame
plan (:mod:`skeleton_mamba.tasks.motion.retarget.live`) gives every frame of a dance the local
rotations :func:`~skeleton_mamba.tasks.motion.retarget.transfer.retarget` gives the whole clip, and the hips'
path but for the constant floor lift (a Mixamo-named A-pose with rolled rests, a VRM 1.0 with meaningless
names). In a real headless Chromium (:mod:`browser_page`): the page loads the character with GLTFLoader, a
picked music file makes its bones move, every bone's local rotation and the hips' position the page sets equal
the plan applied in Python to the joints the page shows (float32), the character's skinned vertices are where
those rotations put them (the bone-to-tip directions of the rig equal the dancer's), and the page makes no
request and logs no error. A BVH rig (no mesh) and a rig without feet are refused in one line before the
checkpoint is read.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import soundfile as sf
import torch
from scipy.spatial.transform import Rotation

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.formats.motion_reader import load_skeleton_motion
from skeleton_mamba.tasks.motion.retarget.live import apply_live_plan, live_plan
from skeleton_mamba.tasks.motion.retarget.rig import find_bones, load_rig, separate_torso
from skeleton_mamba.tasks.motion.retarget.transfer import retarget
from skeleton_mamba.tasks.motion.synthetic import synthesize_music
from skeleton_mamba.tasks.motion.synthetic.dance import write_dance
from skeleton_mamba.tasks.stream.features import SR, music_features
from skeleton_mamba.tasks.training.cli import main as sm
from tests.helpers.browser_page import READY, Page, browser_or_skip, only_local, ort_web_or_skip
from tests.helpers.checkpoint_files import tiny_stream_checkpoint
from tests.helpers.retarget_rigs import HUMANOID, MIXAMO, build_rig, rest_positions


@pytest.fixture(scope="module")
def rigs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rigs")
    meaningless = {b: f"bone{i}" for i, b in enumerate(HUMANOID)}
    return {
        "glb": build_rig(tmp / "hero.glb", MIXAMO, rest_positions(a_pose=True, legs=1.2), roll_seed=3),
        "vrm": build_rig(tmp / "avatar.vrm", meaningless, rest_positions(scale=0.8), 7, vrm="1"),
        "vrm0": build_rig(tmp / "avatar0.vrm", meaningless, rest_positions(legs=0.9), 8, vrm="0"),
    }


def _source(motion):
    joints = motion.joint_positions()
    bones, _ = find_bones(motion.names, "dance", what="motion")
    return joints, separate_torso(bones, motion.parents, joints)


@pytest.mark.parametrize("kind", ["glb", "vrm"])
def test_the_live_plan_gives_every_frame_the_clips_retarget(rigs, kind, tmp_path):
    motion = load_skeleton_motion(write_dance(tmp_path, bpm=120, duration_s=2.0, style="bounce", seed=4))
    joints, bones = _source(motion)
    rig = load_rig(rigs[kind])
    whole = retarget(rig, joints, bones)
    plan = live_plan(rig, joints[0], bones)
    assert {s["node"] for s in plan["steps"]} == {j for j, _, _ in whole.driven.values()}
    for t in (0, 17, 45):
        local, hips = apply_live_plan(plan, joints[t])
        for j, rotation in local.items():
            np.testing.assert_allclose(rotation, whole.local[j][t], atol=1e-9)
        np.testing.assert_allclose(hips[[0, 2]], whole.hips_translation[t, [0, 2]], atol=1e-9)
        assert abs(hips[1] - whole.hips_translation[t, 1]) < 0.03  # the floor lift: constant live


@pytest.fixture(scope="module", params=["vrm", "vrm0"])
def avatar_site(rigs, tmp_path_factory, request):
    browser_or_skip()
    ort_web_or_skip()
    tmp = tmp_path_factory.mktemp("web_avatar")
    audio = synthesize_music(120.0, 4.0, sr=SR, seed=1).audio
    wav = tmp / "song.wav"
    sf.write(wav, audio, SR, subtype="PCM_16")
    ckpt, _ = tiny_stream_checkpoint(tmp / "dancer.ckpt", torch.from_numpy(music_features(audio, SR)))
    site = tmp / "site"
    assert sm(["export-web", "--ckpt", str(ckpt), "--out", str(site), "--rig", str(rigs[request.param])]) == 0
    return site / "index.html", wav, rigs[request.param]


def test_the_character_dances_in_the_page_as_the_plan_says(avatar_site, rigs, tmp_path):
    page_file, wav, rig_file = avatar_site
    rig = load_rig(rig_file)
    p = Page(page_file.as_uri(), tmp_path)
    try:
        p.wait_for(READY, 120, "the page's start")
        p.set_file("#file", wav)
        p.wait_for("window.smDance.frames >= 40", 60, "40 frames danced")
        seen = []
        for _ in range(2):
            state = p.js("JSON.stringify([window.smDance.shown, window.smDance.avatar])")
            seen.append(state)
            p.wait_for(f"window.smDance.frames >= {p.js('window.smDance.frames') + 5}", 30, "5 more frames")
        shown, pose = json.loads(seen[-1])
        plan = p.js("JSON.parse(document.getElementById('sm-data').textContent).avatar")
        local, hips = apply_live_plan(plan, np.asarray(shown, np.float64).reshape(24, 3))
        assert {int(k) for k in pose["local"]} == set(local)
        for node, rotation in local.items():
            got = Rotation.from_quat(pose["local"][str(node)]).as_matrix()
            np.testing.assert_allclose(got, rotation, atol=2e-4)
        np.testing.assert_allclose(pose["hips"], hips, atol=1e-4)
        first = json.loads(seen[0])[1]
        moved = [
            Rotation.from_quat(first["local"][k]).inv() * Rotation.from_quat(pose["local"][k])
            for k in pose["local"]
        ]
        assert max(r.magnitude() for r in moved) > np.radians(2)  # the bones move with the music
        # the skinned mesh follows: each bone's box centre, where the page's skin puts it, points from the
        # bone to its tip as the dancer's joints do
        shown, vertices = json.loads(p.js("JSON.stringify([smDance.shown, smDance.avatarVertices()])"))
        shown = np.asarray(shown, np.float64).reshape(24, 3)
        centres = np.asarray(vertices[0]).reshape(-1, 8, 3).mean(1)  # one box of 8 vertices per bone
        bones, _ = find_bones(list(SMPL24.joint_names), "dancer", what="motion")
        order = list(rest_positions())
        for bone, tip in (("leftUpperArm", "leftLowerArm"), ("rightUpperLeg", "rightLowerLeg")):
            on_rig = centres[order.index(tip)] - centres[order.index(bone)]
            in_dance = shown[bones[tip]] - shown[bones[bone]]
            cosine = on_rig @ in_dance / np.linalg.norm(on_rig) / np.linalg.norm(in_dance)
            assert cosine > np.cos(np.radians(3)), (bone, np.degrees(np.arccos(cosine)))
        assert p.js("window.smDance.avatarVrm") is True  # drawn by three-vrm's loader
        assert not p.errors, p.errors
        only_local(p.requests)
        assert rig.bones  # the VRM's humanoid map was read (meaningless node names)
        licence = page_file.with_name("LICENSE-three-vrm.txt").read_text()
        assert "pixiv" in licence and "MIT" in licence
    finally:
        p.close()


def test_export_web_refuses_a_rig_it_cannot_draw_before_the_checkpoint(rigs, tmp_path, capsys):
    never = tmp_path / "never.ckpt"
    never.write_bytes(b"not read")
    bvh = tmp_path / "skeleton.bvh"
    bvh.write_text("HIERARCHY\n")
    footless = {b: q for b, q in rest_positions().items() if "Foot" not in b and "Toes" not in b}
    cases = {
        str(bvh): "a skinned .glb or .vrm",
        str(build_rig(tmp_path / "footless.glb", MIXAMO, footless)): "lacks the humanoid bones leftFoot",
    }
    for rig, expected in cases.items():
        out = tmp_path / "site"
        assert sm(["export-web", "--ckpt", str(never), "--out", str(out), "--rig", rig]) == 2
        err = capsys.readouterr().err
        assert expected in err and err.count("\n") == 1, err
        assert not out.exists()
