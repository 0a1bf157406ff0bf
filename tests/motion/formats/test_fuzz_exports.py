"""Hostile inputs to the exporters (issue 43): glTF files, the viewer page, ONNX export options.

Every exporter's glTF passes the Khronos validator (npm ``gltf-validator``; skipped where it is not
installed); motions glTF cannot hold (no frames, a frame rate out of range, more joints than 16-bit
``JOINTS_0`` indices address, non-finite or absurd values) are refused on one line naming the file; every
fps and size option is range-checked where it is parsed; the viewer's embedded data is strict JSON in which
no name, key or value can end the ``<script>`` element.
"""

from __future__ import annotations

import base64
import json
import re
import time

import numpy as np
import pygltflib
import pytest
import soundfile as sf

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.motion.formats.export import write_motion
from skeleton_mamba.tasks.motion.formats.gltf import MAX_JOINTS, from_joints, from_motion_data, write_glb
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion
from skeleton_mamba.tasks.motion.render import view
from skeleton_mamba.tasks.motion.render.view import script_json, write_view
from skeleton_mamba.tasks.training.cli import main as sm
from tests.helpers.gltf_reader import accessor, assert_khronos_valid, glb_joint_positions
from tests.helpers.motions import _smpl_motion
from tests.helpers.repo import shared_file

HOSTILE_NAME = "</script><!--<script>alert(1)//\u2028__DATA__&amp;"


def _one_line_refusal(capsys, args: list[str], path) -> str:
    assert sm(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err and "Traceback" not in err, err
    return err


def _argparse_refusal(capsys, args: list[str]) -> str:
    with pytest.raises(SystemExit) as info:
        sm(args)
    assert info.value.code == 2
    return capsys.readouterr().err.strip().splitlines()[-1]


# ------------------------------------------------------------------------------ the Khronos validator


def test_every_exporter_writes_files_the_khronos_validator_accepts(tmp_path):
    """``sm export`` of every motion format, the dance writer (sm dance / stream, QEAN, the demos), the
    text-to-motion writer (sm generate) and the viewer's embedded files, at the frame-rate bounds."""
    motion = _smpl_motion(12)
    files = []
    save_motion(tmp_path / "smpl.npz", motion)
    save_motion(tmp_path / "joints.npz", MotionData(25.0, skeleton="smpl24", joints=motion.joint_positions()))
    np.save(tmp_path / "joints.npy", motion.joint_positions())
    inputs = [tmp_path / "smpl.npz", tmp_path / "joints.npz", tmp_path / "joints.npy"]
    inputs += [shared_file("bvh/cmu_01_01.bvh"), shared_file("ntu/S001C001P001R001A001.skeleton")]
    inputs += [shared_file("humanml3d/new_joint_vecs/012314.npy")]
    for i, path in enumerate(inputs):
        assert sm(["export", str(path), "--out", str(tmp_path / f"export{i}.glb")]) == 0
        files.append(tmp_path / f"export{i}.glb")
    for fps in ("1", "1000"):
        assert sm(["export", str(tmp_path / "smpl.npz"), "--out", str(tmp_path / f"fps{fps}.glb"),
                   "--motion-fps", fps]) == 0  # fmt: skip
        files.append(tmp_path / f"fps{fps}.glb")
    one_frame = MotionData(30.0, poses=motion.poses[:1], trans=motion.trans[:1], scaling=motion.scaling)
    files.append(write_glb(from_motion_data(one_frame), tmp_path / "one.glb"))
    files.append(write_motion(motion, tmp_path / "dance", "dance", render=False).glb)
    from skeleton_mamba.tasks.text2motion.generate_cli import save_generated

    features = np.load(shared_file("humanml3d/new_joint_vecs/012314.npy"))
    files.append(
        save_generated(__import__("torch").from_numpy(features), "walk", tmp_path / "gen" / "g")["glb"]
    )
    page = write_view([("a", from_motion_data(motion))], tmp_path / "view.html").read_text()
    data = json.loads(
        re.search(r'<script id="sm-data" type="application/json">(.*?)</script>', page, re.S)[1]
    )
    (tmp_path / "embedded.glb").write_bytes(base64.b64decode(data["motions"][0]["glb"]))
    files.append(tmp_path / "embedded.glb")
    for path in files:  # and each re-read: its joints are finite, its key times increase
        _, positions = glb_joint_positions(path)
        assert np.isfinite(positions).all()
    assert_khronos_valid(*files)


def test_joint_indices_use_unsigned_short_and_more_joints_are_refused(tmp_path):
    names = [f"j{i}" for i in range(300)]  # past an UNSIGNED_BYTE
    parents = [-1, *range(299)]
    out = write_glb(from_joints(np.zeros((2, 300, 3)), None, 30.0, parents, names), tmp_path / "300.glb")
    gltf = pygltflib.GLTF2().load(str(out))
    joints_accessor = gltf.meshes[0].primitives[0].attributes.JOINTS_0
    assert gltf.accessors[joints_accessor].componentType == pygltflib.UNSIGNED_SHORT
    np.testing.assert_array_equal(accessor(gltf, gltf.binary_blob(), joints_accessor)[:, 0], np.arange(300))
    assert_khronos_valid(out)
    many = MAX_JOINTS + 1
    motion = from_joints(np.zeros((1, many, 3)), None, 30.0, [-1] * many, [f"j{i}" for i in range(many)])
    with pytest.raises(InputError, match=r"big.glb: 65,536 joints; a glTF skin binds 1 to 65,535"):
        write_glb(motion, tmp_path / "big.glb")
    assert not (tmp_path / "big.glb").exists()


# ------------------------------------------------------------------------------ hostile motions


def _bvh(offset: str = "0 0 0", value: str = "0") -> str:
    return (f"HIERARCHY\nROOT hips\n{{\nOFFSET {offset}\nCHANNELS 3 Xposition Yposition Zposition\n"
            f"JOINT a\n{{\nOFFSET 0 1 0\nCHANNELS 1 Zrotation\nEnd Site\n{{\nOFFSET 0 1 0\n}}\n}}\n}}\n"
            f"MOTION\nFrames: 2\nFrame Time: 0.0333\n0 0 0 0\n0 0 {value} 0\n")  # fmt: skip


HOSTILE_MOTIONS = {
    "zero_frames.npy": (lambda p: np.save(p, np.zeros((0, 24, 3), np.float32)), "zero frames"),
    "zero_frames.npz": (
        lambda p: np.savez(p, smpl_poses=np.zeros((0, 72)), smpl_trans=np.zeros((0, 3)), fps=30.0),
        "motion has no frames",
    ),
    "huge.npy": (lambda p: np.save(p, np.full((3, 24, 3), 1e30, np.float32)), "beyond the plausible"),
    "nan.npy": (lambda p: np.save(p, np.full((3, 24, 3), np.nan, np.float32)), "joints: nan at frame 0"),
    "offset_1e308.bvh": (lambda p: p.write_text(_bvh(offset="1e308 0 0")), "beyond the plausible 1e+08"),
    "value_1e308.bvh": (lambda p: p.write_text(_bvh(value="1e308")), "1e+308 (beyond the plausible 1e+08)"),
}


@pytest.mark.parametrize("command", ["export", "view", "render"])
@pytest.mark.parametrize("case", sorted(HOSTILE_MOTIONS))
def test_hostile_motions_are_refused_on_one_line_naming_the_file(tmp_path, capsys, command, case):
    write, expected = HOSTILE_MOTIONS[case]
    path = tmp_path / case
    write(path)
    out = tmp_path / {"export": "o.glb", "view": "o.html", "render": "o.gif"}[command]
    err = _one_line_refusal(capsys, [command, str(path), "--out", str(out)], path)
    assert expected in err and not out.exists(), err


@pytest.mark.parametrize("command, option", [("export", "--motion-fps"), ("view", "--motion-fps"),
                                             ("render", "--motion-fps"), ("render", "--fps")])  # fmt: skip
@pytest.mark.parametrize("value", ["-30", "0", "inf", "nan", "1e9"])
def test_fps_options_are_range_checked_where_parsed(tmp_path, capsys, command, option, value):
    save_motion(tmp_path / "m.npz", _smpl_motion(4))
    out = tmp_path / ("o.glb" if command == "export" else "o.html" if command == "view" else "o.gif")
    line = _argparse_refusal(
        capsys, [command, str(tmp_path / "m.npz"), "--out", str(out), f"{option}={value}"]
    )
    assert line == (
        f"sm {command}: error: argument {option}: expected a frame rate (frames per second) from 1 to 1000, "
        f"got {value}"
    )
    assert not out.exists()


@pytest.mark.parametrize(
    "option, value, expected",
    [
        ("--frames", "-5", "expected a frame count from 2 to 4,096, got -5"),
        ("--frames", "1000000000", "expected a frame count from 2 to 4,096, got 1,000,000,000"),
        ("--in-channels", "0", "expected a channel count from 1 to 65,536, got 0"),
        ("--in-channels", "x", "expected a channel count from 1 to 65,536, got 'x'"),
    ],
)
def test_export_onnx_counts_are_range_checked(tmp_path, capsys, option, value, expected):
    args = ["export-onnx", "--backbone", "b.yaml", "--out", str(tmp_path / "onnx"), option, value]
    assert _argparse_refusal(capsys, args) == f"sm export-onnx: error: argument {option}: {expected}"


@pytest.mark.parametrize(
    "text, expected",
    [
        ("dim: [1, 2]\n", "SkeletonMambaConfig.dim: expected int, got [1, 2]"),
        ("mixer: 5\n", "SkeletonMambaConfig.mixer: expected a MixerConfig object, got 5"),
        ("- dim\n", "a backbone file holds a mapping of SkeletonMambaConfig fields"),
        ("depth: 1000000000\n", "depth = 1000000000: a size is an integer from 0 to 256"),
        ("mixer: {d_state: 100000000}\n", "mixer.d_state = 100000000: a size is an integer"),
        ("nonsense: 1\n", "SkeletonMambaConfig has no field 'nonsense'"),
        ("dim: [\n", "YAML syntax error in the backbone file"),
    ],
)
def test_export_onnx_refuses_backbone_yaml_of_the_wrong_shape(tmp_path, capsys, text, expected):
    (tmp_path / "b.yaml").write_text(text)
    args = ["export-onnx", "--backbone", str(tmp_path / "b.yaml"), "--out", str(tmp_path / "onnx")]
    err = _one_line_refusal(capsys, args, tmp_path / "b.yaml")
    assert expected in err and not (tmp_path / "onnx").exists(), err


# ------------------------------------------------------------------------------ the viewer page


def _data_block(page: str) -> str:
    return re.search(r'<script id="sm-data" type="application/json">(.*?)</script>', page, re.S)[1]


def test_embedded_data_is_strict_json_no_string_can_break_out_of(tmp_path):
    metrics = {
        HOSTILE_NAME: 1.0,
        "nan": float("nan"),
        "inf": float("inf"),
        "nested": {"<!--": -float("inf"), "ok": 2},
        "flag": True,
    }
    out = write_view(
        [(HOSTILE_NAME, from_motion_data(_smpl_motion(4)))], tmp_path / "v.html", metrics=metrics
    )
    page = out.read_text(encoding="utf-8")
    block = _data_block(page)
    assert "<" not in block and ">" not in block and "&" not in block and "\u2028" not in block
    data = json.loads(block, parse_constant=lambda token: pytest.fail(f"non-strict JSON: {token}"))
    assert data["motions"][0]["name"] == HOSTILE_NAME  # the escapes read back as the original text
    assert data["metrics"] == {
        HOSTILE_NAME: 1.0,
        "nan": None,
        "inf": None,
        "nested.<!--": None,
        "nested.ok": 2,
        "flag": "yes",
    }
    title = re.search(r"<title>(.*?)</title>", page, re.S)[1]
    assert "<" not in title and "&lt;/script&gt;" in title and "__DATA__" in title  # not substituted again
    assert page.count("<script") == page.count("</script>")


def test_script_json_refuses_non_finite_numbers():
    with pytest.raises(ValueError, match="Out of range float values"):
        script_json({"x": float("nan")})


def test_metrics_file_goes_through_the_bounded_reader(tmp_path, monkeypatch):
    motion = [("m", from_motion_data(_smpl_motion(4)))]
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 10_000 + "]" * 10_000)
    with pytest.raises(InputError, match=r"deep.json:1:65: nested more than 64 levels deep"):
        write_view(motion, tmp_path / "v.html", metrics=deep)
    values = tmp_path / "values.json"
    values.write_text('{"FID": NaN, "Div": Infinity, "big": 1e400, "ok": 1.5}')
    page = write_view(motion, tmp_path / "v.html", metrics=values).read_text()
    assert json.loads(_data_block(page))["metrics"] == {"FID": None, "Div": None, "big": None, "ok": 1.5}
    monkeypatch.setattr(view, "MAX_METRICS_BYTES", 10)
    with pytest.raises(InputError, match=r"values.json: 54 bytes, more than a metrics file's 10"):
        write_view(motion, tmp_path / "w.html", metrics=values)
    assert not (tmp_path / "w.html").exists()


def test_music_must_be_audio_of_bounded_size(tmp_path, monkeypatch):
    motion = [("m", from_motion_data(_smpl_motion(4)))]
    fake = tmp_path / "notes.wav"
    fake.write_text("my notes, not audio")
    with pytest.raises(Exception, match="notes.wav") as info:
        write_view(motion, tmp_path / "v.html", music=fake)
    assert "audio" in str(info.value) or "WAV" in str(info.value)
    wav = tmp_path / "song.wav"
    sf.write(wav, np.zeros(8000, np.float32), 8000)
    monkeypatch.setattr(view, "MAX_MUSIC_BYTES", 1000)
    with pytest.raises(InputError, match=r"song.wav: 16,044 bytes, more than a music file to embed's 1,000"):
        write_view(motion, tmp_path / "v.html", music=wav)
    assert not (tmp_path / "v.html").exists()


def test_a_page_of_hostile_names_and_metrics_opens_and_runs_in_chromium(tmp_path):
    """The page whose names, keys and values tried to close its script still runs in a real browser."""
    from tests.helpers.browser_page import Page, browser_or_skip

    browser_or_skip()
    metrics = {"<!--<script>": float("nan"), "</script>": 1.25}
    out = write_view(
        [(HOSTILE_NAME, from_motion_data(_smpl_motion(8)))], tmp_path / "v.html", metrics=metrics
    )
    page = Page(out.as_uri(), tmp_path)
    try:
        deadline = time.time() + 60
        while not page.js("typeof window.smViewer === 'object'") and time.time() < deadline:
            time.sleep(0.2)
        assert page.js("typeof window.smViewer === 'object'"), "the page's script did not run"
        text = page.js("document.getElementById('info').textContent")
        assert HOSTILE_NAME in text and "<!--<script>: null" in text and "</script>: 1.250" in text, text
        assert not page.errors, page.errors
    finally:
        page.close()
