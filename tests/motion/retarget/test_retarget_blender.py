"""``sm retarget``'s outputs imported by Blender (``bpy``, in a subprocess): the same frame count, duration
and joint heights as the file says (slow: ``pytest -m slow``; skipped when ``bpy`` is not installed)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.commands.retarget_cli import main as retarget_main
from skeleton_mamba.tasks.motion.formats.bvh import load_bvh
from skeleton_mamba.tasks.motion.synthetic.dance import write_dance
from tests.helpers.retarget_rigs import HUMANOID, MIXAMO, build_rig, read_animated, rest_positions

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        importlib.util.find_spec("bpy") is None, reason="Blender's bpy is not installed (pip install bpy)"
    ),
]

_SCRIPT = """
import json, sys
import bpy
path, fps, kind = sys.argv[1], float(sys.argv[2]), sys.argv[3]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.context.scene.render.fps = int(round(fps))
if kind == "gltf":
    bpy.ops.import_scene.gltf(filepath=path)
else:
    bpy.ops.import_anim.bvh(filepath=path, global_scale=1.0, use_fps_scale=False, update_scene_fps=True,
                            update_scene_duration=True)
arm = [o for o in bpy.data.objects if o.type == "ARMATURE"][0]
start, end = arm.animation_data.action.frame_range
frames = {}
for f in (int(start), int(round((start + end) / 2)), int(round(end))):
    bpy.context.scene.frame_set(f)
    frames[f] = {pb.name: list(arm.matrix_world @ pb.head) for pb in arm.pose.bones}
print("RESULT" + json.dumps({"range": [start, end], "fps": bpy.context.scene.render.fps, "heads": frames}))
"""


def _blender(path: Path, fps: float, kind: str) -> dict:
    done = subprocess.run([sys.executable, "-c", _SCRIPT, str(path), str(fps), kind], capture_output=True,
                          text=True, timeout=600)  # fmt: skip
    lines = [line for line in done.stdout.splitlines() if line.startswith("RESULT")]
    assert lines, done.stderr[-2000:]
    return json.loads(lines[-1][len("RESULT") :])


def test_blender_imports_gltf_and_vrm(tmp_path):
    dance = write_dance(tmp_path, bpm=120, duration_s=2.0, seed=4)
    positions = rest_positions(a_pose=True)
    for name, vrm in (("mixamo.glb", None), ("avatar.vrm", "1")):
        names = MIXAMO if vrm is None else {b: f"n{i}" for i, b in enumerate(HUMANOID)}
        rig = build_rig(tmp_path / name, names, positions, roll_seed=3, armature_scale=0.01, vrm=vrm)
        out = tmp_path / f"out_{name}"
        assert retarget_main([str(dance), "--rig", str(rig), "--out", str(out)]) == 0
        _, times, world, _ = read_animated(out)
        frames, fps = len(times), 30.0
        got = _blender(out, fps, "gltf")
        start, end = got["range"]
        assert round(end - start) + 1 == frames and (round(end - start) + 1) / got["fps"] == frames / fps
        for f, heads in got["heads"].items():
            i = int(f) - int(round(start))
            for b, node in ((b, i_ + 1) for i_, b in enumerate(HUMANOID)):
                x, y, z = world[i, node, :3, 3]
                np.testing.assert_allclose(heads[names[b]], [x, -z, y], atol=0.01)  # Blender is Z up
            height = max(h[2] for h in heads.values())
            assert abs(height - world[i, 1:-1, 1, 3].max()) < 0.01


def test_blender_imports_bvh(tmp_path):
    cmu = Path("/work/shared/data/bvh/cmu_01_01.bvh")
    if not cmu.is_file():
        pytest.skip(f"no CMU BVH at {cmu}")
    dance = write_dance(tmp_path, bpm=120, duration_s=2.0, seed=4)
    out = tmp_path / "cmu_dance.bvh"
    assert retarget_main([str(dance), "--rig", str(cmu), "--out", str(out)]) == 0
    written = load_bvh(out)
    got = _blender(out, written.fps, "bvh")
    start, end = got["range"]
    assert round(end - start) + 1 == written.num_frames and got["fps"] == written.fps
    heights = written.joint_positions()[:, :, 1].max(1)  # file units, Y up
    for f, heads in got["heads"].items():
        i = int(f) - int(round(start))
        assert abs(max(h[2] for h in heads.values()) - heights[i]) < 0.01 * heights[i]
