"""Skeleton rendering: frame counts and durations read back with ffmpeg, music muxing, input kinds."""

from __future__ import annotations

import subprocess

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image
from scipy.io import wavfile

from skeleton_mamba.skeletons import HUMANML3D22, SMPL24
from skeleton_mamba.tasks.motion.body.smpl import SMPL_REST_OFFSETS
from skeleton_mamba.tasks.motion.commands.render_cli import main
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, save_motion
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints
from skeleton_mamba.tasks.motion.render.skeleton import (
    RenderStyle,
    fit_cameras,
    joint_sides,
    render_frames,
    render_motion,
)
from skeleton_mamba.tasks.training.cli import main as sm_main


def dancing_smpl(frames: int, fps: float, seed: int = 0) -> MotionData:
    rng = np.random.default_rng(seed)
    t = np.arange(frames)[:, None, None] / fps
    poses = 0.4 * np.sin(2 * np.pi * 1.5 * t + rng.uniform(0, 6, size=(1, 24, 3)))
    trans = np.stack(
        [0.3 * np.sin(t[:, 0, 0]), 0.9 + 0.05 * np.cos(4 * t[:, 0, 0]), 0.2 * t[:, 0, 0]], axis=1
    )
    return MotionData(fps=fps, poses=poses, trans=trans)


def audio_streams(path) -> str:
    """ffmpeg's description of the file's streams (it exits non-zero without an output: ignore)."""
    proc = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True
    )
    return proc.stderr.decode(errors="replace")


def test_two_second_mp4_with_music_has_the_right_frames_and_duration(tmp_path):
    motion = save_motion(tmp_path / "dance.npz", dancing_smpl(60, 30.0))
    rate = 22050
    tone = (0.2 * np.sin(2 * np.pi * 440 * np.arange(5 * rate) / rate) * 32767).astype(np.int16)
    wavfile.write(tmp_path / "music.wav", rate, tone)  # 5 s of music, cut to the 2 s motion
    out = tmp_path / "clip.mp4"
    assert main([str(motion), "--music", str(tmp_path / "music.wav"), "--out", str(out), "--quiet"]) == 0
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(out))
    assert frames == 60
    assert seconds == pytest.approx(2.0, abs=0.05)
    info = audio_streams(out)
    assert "Audio: aac" in info and "Video: h264" in info


def test_resampled_output_fps_and_gif(tmp_path):
    motion = save_motion(tmp_path / "dance.npz", dancing_smpl(121, 60.0))  # 2 s at 60 fps
    out = tmp_path / "clip.mp4"
    assert main([str(motion), "--out", str(out), "--fps", "15", "--quiet"]) == 0
    assert imageio_ffmpeg.count_frames_and_secs(str(out)) == (31, pytest.approx(31 / 15, abs=0.05))
    gif = tmp_path / "clip.gif"
    assert main([str(motion), "--out", str(gif), "--fps", "10", "--quiet"]) == 0
    with Image.open(gif) as image:
        assert image.n_frames == 21 and image.info["duration"] == 100 and image.size == (640, 480)


def test_frames_show_the_skeleton_where_it_projects(tmp_path):
    rest = np.zeros((24, 3))
    for j, p in enumerate(SMPL24.parents):
        if p >= 0:
            rest[j] = rest[p] + SMPL_REST_OFFSETS[j]
    joints = np.repeat(rest[None], 3, axis=0) + [0.0, 1.0, 0.0]
    style = RenderStyle(width=160, height=128)
    images = list(render_frames(joints, SMPL24.parents, 30.0, names=SMPL24.joint_names, style=style))
    assert len(images) == 3 and images[0].shape == (128, 160, 3) and images[0].dtype == np.uint8
    blue = (images[0][..., 2] > 150) & (images[0][..., 0] < 120)  # left side
    red = (images[0][..., 0] > 150) & (images[0][..., 2] < 120)  # right side
    assert blue.sum() > 20 and red.sum() > 20
    # The camera looks at the body from +z (rotated 30 degrees towards +x): the subject's left
    # (+x in SMPL) appears on the image's right.
    assert np.nonzero(blue)[1].mean() > np.nonzero(red)[1].mean()


def smpl_rest() -> np.ndarray:
    """(24, 3) SMPL rest joints, root at the origin."""
    rest = np.zeros((24, 3))
    for j, p in enumerate(SMPL24.parents):
        if p >= 0:
            rest[j] = rest[p] + SMPL_REST_OFFSETS[j]
    return rest


def jumping_and_travelling(frames: int = 90, fps: float = 30.0) -> np.ndarray:
    """(T, 24, 3): a standing body that jumps 1.2 m high, dashes 4 m sideways and raises its arms."""
    t = np.arange(frames) / fps
    joints = np.repeat(smpl_rest()[None], frames, axis=0) + [0.0, 0.95, 0.0]
    joints[:, :, 1] += 1.2 * np.clip(np.sin(2 * np.pi * t / (t[-1] + 1 / fps)), 0, None)[:, None]  # one jump
    joints[:, :, 0] += 4.0 / (1 + np.exp(-(t - 1.5) * 12))[:, None]  # a quick 4 m step: the camera lags
    arms = [16, 17, 18, 19, 20, 21, 22, 23]  # shoulders .. hands straight up in the second half
    up = t > t[-1] / 2
    joints[np.ix_(up, arms, [1])] += np.linspace(0.3, 0.9, len(arms))[None, :, None]
    return joints


@pytest.mark.parametrize(("width", "height"), [(160, 128), (480, 352), (128, 256)])
def test_every_joint_of_every_frame_projects_inside_the_image(width, height):
    joints = jumping_and_travelling()
    style = RenderStyle(width=width, height=height)
    cameras = fit_cameras(joints, SMPL24.parents, 30.0, style)
    margin = style.margin_fraction * height
    for frame, camera in zip(joints, cameras):
        # an independent pinhole projection from the camera's eye, target and focal length
        forward = (camera.target - camera.eye) / np.linalg.norm(camera.target - camera.eye)
        right = np.cross(forward, [0.0, 1.0, 0.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        rel = frame - camera.eye
        z = rel @ forward
        assert (z > 0).all()
        u = width / 2 + camera.focal * (rel @ right) / z
        v = height / 2 - camera.focal * (rel @ up) / z
        assert (u >= margin - 1e-6).all() and (u <= width - margin + 1e-6).all()
        assert (v >= margin - 1e-6).all() and (v <= height - margin + 1e-6).all()
    # fitted, not just far away: the farthest joint from the centre, as a fraction of the room to the margin
    room = np.array([width / 2 - margin, height / 2 - margin])
    extent = max(
        (np.abs(c.pixels(c.to_camera(f)) - [width / 2, height / 2]) / room).max()
        for f, c in zip(joints, cameras)
    )
    assert 0.85 < extent <= 1 + 1e-9
    if width < height:  # the narrow image: the 4 m step binds the fit exactly
        assert extent == pytest.approx(1.0)


def test_rendered_body_never_touches_the_image_border():
    joints = jumping_and_travelling()
    background = (255, 255, 255)
    # grid and shadow in the background colour: only the body (and the time stamp) is drawn
    style = RenderStyle(width=160, height=128, grid=background, shadow=background, background=background)
    border = 3
    for image in render_frames(joints, SMPL24.parents, 30.0, names=SMPL24.joint_names, style=style):
        drawn = (image != 255).any(axis=2)
        assert drawn.sum() > 50  # the body is there
        edge = np.ones_like(drawn)
        edge[border:-border, border:-border] = False
        assert not (drawn & edge).any()


def test_joint_sides_from_names():
    assert joint_sides(["left_hip", "right_knee", "spine1"]) == [-1, 1, 0]
    assert joint_sides(["LeftUpLeg", "RHipJoint", "LHipJoint", "Hips", "lowerback"]) == [-1, 1, -1, 0, 0]


def test_inputs_of_every_kind(tmp_path, shared_data):
    joints22 = np.random.default_rng(0).normal(size=(8, 22, 3))
    np.save(tmp_path / "h.npy", joints22)
    clip = load_joints(tmp_path / "h.npy")
    assert clip.fps == 20.0 and clip.parents == list(HUMANML3D22.parents)
    np.save(tmp_path / "n.npy", np.zeros((4, 25, 3)))
    assert load_joints(tmp_path / "n.npy").fps == 30.0
    with pytest.raises(ValueError, match="cannot infer a skeleton for 7 joints"):
        np.save(tmp_path / "x.npy", np.zeros((4, 7, 3)))
        load_joints(tmp_path / "x.npy")
    bvh = load_joints(shared_data / "bvh" / "cmu_01_01.bvh")
    assert bvh.joints.shape == (2752, 31, 3) and bvh.fps == 120.0
    ntu = load_joints(shared_data / "ntu" / "S001C001P001R001A001.skeleton")
    assert ntu.joints.shape[1] == 25 and ntu.fps == 30.0 and ntu.parents[0] == -1
    out = render_motion(
        ntu.joints[:10], ntu.parents, tmp_path / "ntu.gif", ntu.fps, names=ntu.names, progress=False
    )
    with Image.open(out) as image:
        assert image.n_frames == 10


def test_cli_errors_return_2(tmp_path, capsys):
    assert sm_main(["render", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "a.mp4")]) == 2
    assert "missing.npz: no such motion file" in capsys.readouterr().err
    np.save(tmp_path / "j.npy", np.zeros((4, 24, 3)))
    assert sm_main(["render", str(tmp_path / "j.npy"), "--out", str(tmp_path / "a.avi")]) == 2
    assert "output must end in .mp4 or .gif" in capsys.readouterr().err


def test_bad_joints_fail_before_writing(tmp_path):
    joints = np.zeros((5, 24, 3))
    joints[2, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        render_motion(joints, SMPL24.parents, tmp_path / "nan.mp4", 30.0, progress=False)
    with pytest.raises(ValueError, match=r"joints must be \(T>0, 24, 3\)"):
        render_motion(np.zeros((5, 22, 3)), SMPL24.parents, tmp_path / "bad.mp4", 30.0, progress=False)
    assert not (tmp_path / "nan.mp4").exists() and not (tmp_path / "bad.mp4").exists()


def test_fast_motion_rendered_at_30_fps_unless_asked(tmp_path, capsys):
    motion = dancing_smpl(48, 120.0)  # 0.4 s at 120 fps
    save_motion(tmp_path / "fast.npz", motion)
    assert main([str(tmp_path / "fast.npz"), "--out", str(tmp_path / "a.gif"), "--quiet"]) == 0
    assert "120 fps rendered at 30 fps (frames resampled; --fps N to change)" in capsys.readouterr().err
    with Image.open(tmp_path / "a.gif") as image:  # frames at 0, 1/30, ... up to 47/120 s
        assert image.n_frames == 12
    assert (
        main([str(tmp_path / "fast.npz"), "--out", str(tmp_path / "b.gif"), "--quiet", "--fps", "120"]) == 0
    )
    assert "resampled" not in capsys.readouterr().err
    with Image.open(tmp_path / "b.gif") as image:
        assert image.n_frames == 48


def test_output_file_needs_an_existing_folder(tmp_path, capsys):
    save_motion(tmp_path / "m.npz", dancing_smpl(4, 30.0))
    out = tmp_path / "no" / "such" / "clip.mp4"
    assert sm_main(["render", str(tmp_path / "m.npz"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"sm render: error: {out}: the folder {out.parent} does not exist; create it first "
                   "(--out FILE must be in an existing folder)"]  # fmt: skip
    assert not (tmp_path / "no").exists()
    for command in (["export"], ["view"]):
        target = tmp_path / "no" / f"x.{'glb' if command == ['export'] else 'html'}"
        assert sm_main([*command, str(tmp_path / "m.npz"), "--out", str(target)]) == 2
        assert "does not exist; create it first" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()
