"""Hostile scene files for ``sm make-ego`` (issue 43): refused on one line, in bounded time, nothing left.

Empty and garbage files, a NaN vertex, and triangle counts beyond the stated bound (checked from what the
file declares before it is loaded or ray cast: a PLY header, glTF accessors counted once per instancing
node, OBJ face lines, a binary STL's count).
"""

from __future__ import annotations

import json
import struct
import time

import pytest

from skeleton_mamba.tasks.egodance.builder.scene import load_scene
from skeleton_mamba.tasks.egodance.builder.scene_check import (
    MAX_SCENE_FACES,
    SceneFileError,
    check_scene_file,
)
from skeleton_mamba.tasks.motion.formats.motion_file import save_motion
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance
from skeleton_mamba.tasks.training.cli import main as sm


def _ply_header(faces: int) -> str:
    return (
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {faces}\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 0 1\n"
    )


def _instancing_bomb(nodes: int) -> dict:
    """A glTF of one 1000-triangle mesh instanced by ``nodes`` nodes (no buffer needed to be counted)."""
    return {
        "asset": {"version": "2.0"},
        "accessors": [{"componentType": 5125, "count": 3000, "type": "SCALAR"},
                      {"componentType": 5126, "count": 3, "type": "VEC3"}],
        "meshes": [{"primitives": [{"indices": 0, "attributes": {"POSITION": 1}}]}],
        "nodes": [{"mesh": 0} for _ in range(nodes)],
    }  # fmt: skip


def _glb(document: dict) -> bytes:
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    return b"glTF" + struct.pack("<II", 2, 20 + len(text)) + struct.pack("<II", len(text), 0x4E4F534A) + text


HOSTILE_SCENES = {
    "empty.obj": (b"", "the scene contains no triangles"),
    "garbage.glb": (b"glTF\x02\x00\x00\x00" + b"\xff" * 100, "not JSON of at most"),
    "garbage.ply": (b"ply\nthis is not a mesh\n", "no 'ply' ... 'end_header' header"),
    "nan_vertex.obj": (b"v 0 0 0\nv 1 0 0\nv 0 0 nan\nf 1 2 3\n", "vertex 2 is [0.0, 0.0, nan]"),
    "nan_vertex.ply": (_ply_header(1).replace("0 0 1\n", "nan 0 1\n").encode() + b"3 0 1 2\n", "vertex 2"),
    "ten_million.ply": (_ply_header(10_000_000).encode() + b"3 0 1 2\n", "10,000,000 triangles, more than"),
    "instanced.glb": (_glb(_instancing_bomb(10_000)), "10,000,000 triangles, more than the 5,000,000"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE_SCENES))
def test_sm_make_ego_refuses_hostile_scenes_on_one_line(tmp_path, capsys, case):
    data, expected = HOSTILE_SCENES[case]
    scene = tmp_path / case
    scene.write_bytes(data)
    save_motion(tmp_path / "m" / "dance.npz", synthesize_dance(120, 1.0, 10, "sway", 0))
    out = tmp_path / "out"
    args = ["make-ego", "--motion", str(tmp_path / "m"), "--scenes", str(scene), "--out", str(out)]
    args += [
        "--fps",
        "10",
        "--window",
        "1",
        "--width",
        "8",
        "--height",
        "8",
        "--workers",
        "1",
        "--quiet",
    ]
    start = time.monotonic()
    assert sm(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(scene) in err and expected in err, err
    assert time.monotonic() - start < 60
    assert not out.exists()  # nothing left behind: the folder the build created is removed


def test_declared_counts_are_read_per_format(tmp_path):
    obj = tmp_path / "quads.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n" + "f 1 2 3 4\n" * 7)
    with pytest.raises(SceneFileError, match=r"quads.obj: 14 triangles, more than the 13"):
        check_scene_file(obj, max_faces=13)  # a quad is two triangles
    check_scene_file(obj, max_faces=14)
    stl = tmp_path / "big.stl"
    stl.write_bytes(b"\0" * 80 + struct.pack("<I", 3) + b"\0" * 150)  # a binary STL's count
    with pytest.raises(SceneFileError, match="big.stl: 3 triangles, more than the 2"):
        check_scene_file(stl, max_faces=2)
    gltf = tmp_path / "bomb.gltf"
    gltf.write_text(json.dumps(_instancing_bomb(3)))
    with pytest.raises(SceneFileError, match="bomb.gltf: 3,000 triangles, more than the 2,999"):
        check_scene_file(gltf, max_faces=2999)


def test_the_bound_is_the_loaders_too(shared_data, tmp_path):
    room = shared_data / "scenes" / "simple_room.glb"
    scene = load_scene(room, "z")
    faces = len(scene.mesh.faces)
    assert faces < MAX_SCENE_FACES
    with pytest.raises(SceneFileError, match=f"simple_room.glb: .* triangles, more than the {faces - 1:,}"):
        load_scene(room, "z", max_faces=faces - 1)
