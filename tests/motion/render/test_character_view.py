"""``sm view`` of a character (``sm retarget``'s output onto a skinned rig built in code,
:mod:`retarget_rigs`): the page draws the character's own mesh with three.js's GLTFLoader and plays its
animation. Checked in a real headless Chromium (:mod:`browser_page`) against an independent reading of the
written file: every vertex the page's skin puts in the world equals the file's node animation composed by the
glTF rule (world = parent @ T R S, :func:`retarget_rigs.read_animated`) times the skin's inverse bind matrix,
at two times; the mesh moves between them; no console error, no request."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib
import pytest

from skeleton_mamba.tasks.motion.formats.gltf import write_glb
from skeleton_mamba.tasks.motion.formats.motion_reader import load_skeleton_motion
from skeleton_mamba.tasks.motion.render.character import read_character
from skeleton_mamba.tasks.motion.synthetic.dance import write_dance
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.browser_page import Page, browser_or_skip
from tests.helpers.retarget_rigs import MIXAMO, build_rig, read_animated, rest_positions


@pytest.fixture(scope="module")
def character(tmp_path_factory) -> Path:
    """A 2 s dance on a Mixamo-named A-pose rig with rolled rests (``sm retarget``)."""
    tmp = tmp_path_factory.mktemp("character")
    dance = write_dance(tmp, bpm=120, duration_s=2.0, style="bounce", seed=2)
    rig = build_rig(tmp / "hero.glb", MIXAMO, rest_positions(a_pose=True), roll_seed=4)
    out = tmp / "hero_dance.glb"
    assert sm_main(["retarget", str(dance), "--rig", str(rig), "--out", str(out)]) == 0
    return out


def _expected_vertices(path: Path, frame: int) -> np.ndarray:
    """(V, 3) the skinned mesh's vertices at ``frame``: W(the vertex's joint) @ IBM @ v (weights 1)."""
    gltf, _, world, _ = read_animated(path)
    blob = gltf.binary_blob()

    def accessor(index: int, dtype) -> np.ndarray:
        acc = gltf.accessors[index]
        view = gltf.bufferViews[acc.bufferView]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc.type]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        return np.frombuffer(blob, dtype, acc.count * width, start).reshape(acc.count, width)

    attributes = gltf.meshes[0].primitives[0].attributes
    vertices = accessor(attributes.POSITION, np.float32).astype(np.float64)
    joints = accessor(attributes.JOINTS_0, np.uint16)[:, 0]
    skin = gltf.skins[0]
    inverse_bind = accessor(skin.inverseBindMatrices, np.float32).reshape(-1, 4, 4).transpose(0, 2, 1)
    nodes = np.asarray(skin.joints)[joints]
    homogeneous = np.concatenate([vertices, np.ones((len(vertices), 1))], 1)
    moved = np.einsum(
        "vij,vjk,vk->vi", world[frame, nodes], inverse_bind[joints].astype(np.float64), homogeneous
    )
    return moved[:, :3]


def test_read_character_tells_a_character_from_a_motion_file(character, tmp_path):
    found = read_character(character)
    assert found is not None and found.animated and found.data == character.read_bytes()
    gltf = pygltflib.GLTF2().load_binary(str(character))
    assert gltf.nodes[found.hips].name == MIXAMO["hips"]
    dance = write_dance(tmp_path, bpm=100, duration_s=1.0)
    motion_glb = write_glb(load_skeleton_motion(dance), tmp_path / "m.glb")
    assert read_character(motion_glb) is None  # sm export's joint points: drawn as a skeleton
    assert read_character(dance) is None


def test_sm_view_draws_the_characters_own_mesh_where_its_file_puts_it(character, tmp_path):
    browser_or_skip()
    out = tmp_path / "view.html"
    assert sm_main(["view", str(character), "--out", str(out)]) == 0
    page = Page(out.as_uri(), tmp_path)
    try:
        page.wait_for_viewer()
        assert page.js("window.smViewer.skinnedMeshes(0)") == 1
        count = page.js("window.smViewer.skinnedVertexCount(0, 0)")
        fps = read_animated(character)[0].animations[0].extras["fps"]
        offset = np.asarray(page.js("window.smViewer.offset(0)"))
        seen = {}
        for frame in (10, 45):
            page.js(f"window.smViewer.seek({frame / fps})")
            got = np.array(
                page.js(f"[...Array({count}).keys()].map(k => window.smViewer.skinnedVertex(0, 0, k))")
            )
            expected = _expected_vertices(character, frame) + offset
            np.testing.assert_allclose(got, expected, atol=1e-3)
            seen[frame] = got
        assert np.abs(seen[45] - seen[10]).max() > 0.05  # the mesh moves
        assert page.errors == [] and all(u.startswith(("data:", "file:", "blob:")) for u in page.requests)
        image, _ = page.screenshot()
        assert image.reshape(-1, 3).std(axis=0).max() > 5, "the canvas is blank"
    finally:
        page.close()


def test_sm_render_draws_the_characters_mesh_where_the_skin_puts_it(character, tmp_path):
    """``sm render`` of the character: every frame of its animation, and in a frame each box of the mesh
    (8 vertices around its bone) drawn in the mesh's colour where the file's skinning puts it."""
    import imageio

    from skeleton_mamba.tasks.motion.render.character_mesh import read_character_mesh
    from skeleton_mamba.tasks.motion.render.mesh import mesh_frames
    from skeleton_mamba.tasks.motion.render.skeleton import RenderStyle, fit_cameras

    out = tmp_path / "hero.mp4"
    assert sm_main(["render", str(character), "--out", str(out)]) == 0
    frames = read_animated(character)[1]
    assert imageio.get_reader(out).count_frames() == len(frames)
    mesh = read_character_mesh(character)
    style = RenderStyle()
    joints = mesh.joint_positions()
    camera = fit_cameras(joints, [-1] * joints.shape[1], mesh.fps, style)[40]
    image = list(mesh_frames(mesh, style))[40]
    expected = _expected_vertices(character, 40)  # the independent skinning of the test
    centres = camera.pixels(camera.to_camera(expected.reshape(-1, 8, 3).mean(1)))
    for x, y in np.round(centres).astype(int):
        patch = image[y - 1 : y + 2, x - 1 : x + 2].reshape(-1, 3).astype(int)
        assert (patch[:, 2] - patch[:, 0]).max() > 10, (x, y)  # the mesh's blue-grey, not the grey floor
    assert np.abs(mesh.posed(40) - expected).max() < 1e-9
