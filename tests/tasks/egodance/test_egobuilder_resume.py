"""``sm make-ego``: resuming checks the files of complete samples; --skip-bad passes corrupt motions."""

from __future__ import annotations

import numpy as np
import pytest

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.tasks.egodance.builder import layout
from skeleton_mamba.tasks.egodance.builder.build import BuildConfig, run_build
from skeleton_mamba.tasks.egodance.builder.make_ego_cli import main as make_ego_main
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance
from tests.helpers.motions import _motion


def _config(out, **kw):
    return BuildConfig(out=str(out), scenes="procedural", num_rooms=1, fps=10, window_s=1.0, width=16,
                       height=16, progress=False, workers=1, **kw)  # fmt: skip


def test_resume_rebuilds_complete_samples_whose_files_were_cut(tmp_path):
    motion = _motion(tmp_path / "motions", seconds=3.0)
    out = tmp_path / "ego"
    assert run_build(_config(out), motion).complete == 3
    a, b, c = layout.complete_samples(out)
    assert [layout.sample_problem(s) for s in (a, b, c)] == [None, None, None]
    video = (a / "rgb.mp4").read_bytes()
    (a / "rgb.mp4").write_bytes(video[: len(video) // 2])  # truncated, COMPLETE marker still there
    with np.load(b / "depth.npz") as data:
        np.savez_compressed(b / "depth.npz", depth=data["depth"][:-3])  # 7 depth frames for 10
    assert layout.sample_problem(a) is not None
    assert "depth.npz" in layout.sample_problem(b) and "10" in layout.sample_problem(b)
    stamp = (c / "meta.json").stat().st_mtime_ns
    again = run_build(_config(out), motion)
    assert (again.rebuilt, again.placed, again.already_complete, again.complete) == (2, 2, 1, 3)
    assert [layout.sample_problem(s) for s in (a, b, c)] == [None, None, None]
    assert len(layout.read_frames(a)) == 10
    assert (c / "meta.json").stat().st_mtime_ns == stamp  # the intact sample was left alone


def test_png_frames_are_counted_too(tmp_path):
    out = tmp_path / "ego"
    run_build(_config(out, frame_format="png"), _motion(tmp_path / "motions", seconds=1.0))
    (sample,) = layout.complete_samples(out)
    assert layout.sample_problem(sample) is None
    sorted((sample / "rgb").glob("*.png"))[-1].unlink()
    assert "rgb/" in layout.sample_problem(sample)


def test_skip_bad_goes_on_past_corrupt_motions_and_lists_them(tmp_path, capsys):
    folder = tmp_path / "motions"
    _motion(folder)
    (folder / "broken.npz").write_bytes(b"PK\x03\x04 not really a zip")
    poisoned = synthesize_dance(120, 2.0, 10.0, "bounce", 2)
    arrays = {"fps": np.asarray(10.0), "smpl_poses": poisoned.poses.reshape(-1, 72).copy(),
              "smpl_trans": poisoned.trans, "smpl_scaling": np.ones(1)}  # fmt: skip
    arrays["smpl_poses"][5, 7] = np.nan
    np.savez(folder / "poisoned.npz", **arrays)
    with pytest.raises(
        DataFileError, match=r"broken.npz.* \(--skip-bad goes on past corrupt motion files\)$"
    ):
        run_build(_config(tmp_path / "stop"), folder)
    summary = run_build(_config(tmp_path / "ego", skip_bad=True), folder)
    assert summary.complete == 2  # the good motion's two windows
    assert len(summary.bad_inputs) == 2
    assert "broken.npz" in summary.bad_inputs[0]
    assert "poisoned.npz" in summary.bad_inputs[1] and "nan at frame 5" in summary.bad_inputs[1]
    options = "--scenes procedural --num-rooms 1 --fps 10 --window 1 --width 16 --height 16 --workers 1"
    argv = ["--motion", str(folder), "--out", str(tmp_path / "cli"), "--skip-bad", "--no-progress"]
    code = make_ego_main(argv + options.split())
    assert code == 0
    printed = capsys.readouterr().out
    assert "skipped 2 corrupt motion files" in printed and "poisoned.npz" in printed
