"""An independent glTF reader for the tests: pygltflib and a numpy forward kinematics written here (the glTF
rule world = parent @ T(t) R(q), quaternions x y z w), sharing no code with the writer."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pygltflib
import pytest

NPM = Path(os.environ.get("SM_NPM_CACHE", Path.home() / ".cache" / "skeleton_mamba" / "npm"))
VALIDATOR = NPM / "node_modules" / "gltf-validator"
_VALIDATE = (
    "const v=require(process.argv[1]);const fs=require('fs');"
    "Promise.all(process.argv.slice(2).map(f=>v.validateBytes(new Uint8Array(fs.readFileSync(f)))))"
    ".then(r=>console.log(JSON.stringify(r.map(x=>x.issues))))"
)


def assert_khronos_valid(*files: Path) -> None:
    """The Khronos glTF validator (npm ``gltf-validator``, as ``.ci/run`` installs it) finds no error and no
    warning in ``files``; skips the calling test when node or the package is absent."""
    node = shutil.which("node")
    if node is None or not VALIDATOR.is_dir():
        pytest.skip(f"Khronos validator not run: needs node and `npm install gltf-validator` in {NPM}")
    result = subprocess.run(
        [node, "-e", _VALIDATE, str(VALIDATOR), *map(str, files)], capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    for path, issues in zip(files, json.loads(result.stdout)):
        assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, (path, issues["messages"])


def accessor(gltf: pygltflib.GLTF2, blob: bytes, index: int) -> np.ndarray:
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc.type]
    dtype = {pygltflib.FLOAT: np.float32, pygltflib.UNSIGNED_SHORT: np.uint16}[acc.componentType]
    start = view.byteOffset + (acc.byteOffset or 0)
    return np.frombuffer(blob, dtype, acc.count * width, start).reshape(acc.count, width).astype(np.float64)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def glb_joint_positions(path: Path) -> tuple[list[str], np.ndarray]:
    """Joint names and (T, J, 3) world positions of the joints of the skin, by FK over the node tree."""
    gltf = pygltflib.GLTF2().load(str(path))
    blob = gltf.binary_blob()
    joints = gltf.skins[0].joints
    anim = gltf.animations[0]
    times = accessor(gltf, blob, anim.samplers[0].input)[:, 0]
    frames = len(times)
    local_t = {n: np.repeat([gltf.nodes[n].translation or [0, 0, 0]], frames, 0) for n in joints}
    local_r = {n: np.repeat([gltf.nodes[n].rotation or [0, 0, 0, 1]], frames, 0) for n in joints}
    for ch in anim.channels:
        sampler = anim.samplers[ch.sampler]
        assert np.array_equal(accessor(gltf, blob, sampler.input)[:, 0], times)
        table = local_t if ch.target.path == "translation" else local_r
        table[ch.target.node] = accessor(gltf, blob, sampler.output)
    parent = {c: n for n, node in enumerate(gltf.nodes) for c in node.children or []}
    world: dict[int, np.ndarray] = {}

    def world_of(n: int) -> np.ndarray:
        if n not in world:
            m = np.zeros((frames, 4, 4))
            m[:, 3, 3] = 1
            m[:, :3, 3] = local_t[n]
            m[:, :3, :3] = [_quat_matrix(q) for q in local_r[n]]
            world[n] = world_of(parent[n]) @ m if n in parent else m
        return world[n]

    positions = np.stack([world_of(n)[:, :3, 3] for n in joints], axis=1)
    return [gltf.nodes[n].name for n in joints], positions
