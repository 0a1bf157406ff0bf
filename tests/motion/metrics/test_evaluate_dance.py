"""``sm evaluate-dance``: folders of npz / AIST++ pkl motions scored under a named protocol."""

from __future__ import annotations

import json

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.formats.aistpp import load_aistpp_motion
from skeleton_mamba.tasks.motion.formats.motion_file import MotionData, load_motion, save_motion
from skeleton_mamba.tasks.motion.metrics.evaluation import DanceEvaluation
from skeleton_mamba.tasks.training.cli import main as sm_main


def test_evaluate_dance_json_matches_the_evaluation_of_the_same_files(folders, tmp_path, capsys):
    gen, real, music = folders
    cache = str(tmp_path / "cache")
    args = ["evaluate-dance", str(gen), str(real), "--protocol", "bailando", "--music-dir", str(music)]
    assert sm_main([*args, "--json", "--quiet", "--cache-dir", cache]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["protocol"] == "bailando" and result["generated_files"] == 3 and result["real_files"] == 3
    evaluation = DanceEvaluation("bailando")
    beats = evaluation.protocol.music_beats(music / "mBR0.wav", cache_dir=cache)
    for path in sorted(gen.iterdir()):
        evaluation.add(load_motion(path).joint_positions(), 60, beats)
    for path in sorted(real.iterdir()):
        evaluation.add(load_aistpp_motion(path).joint_positions(), 60, beats, real=True)
    expected = evaluation.compute()
    for key in ("FID_k", "FID_g", "Div_k", "Div_g", "BeatAlign", "BeatAlign_real", "Div_k_real"):
        assert result[key] == pytest.approx(expected[key], rel=1e-9), key
    assert 0.0 < result["BeatAlign"] <= 1.0
    # the table form
    assert sm_main([*args, "--quiet", "--cache-dir", cache]) == 0
    table = capsys.readouterr().out
    assert "protocol bailando: 3 generated files" in table and "BeatAlign" in table and "FID_k" in table


def test_evaluate_dance_edge_reports_pfc_and_clip_counts(folders, capsys):
    gen, real, _ = folders
    assert sm_main(["evaluate-dance", str(gen), str(real), "--protocol", "edge", "--json", "--quiet"]) == 0
    printed = capsys.readouterr()
    result = json.loads(printed.out)
    # 700 frames at 60 fps -> 350 at 30 fps -> clips at 0, 75, 150 (3 per file); 600 -> 300 -> 0, 75, 150
    assert result["generated_clips"] == 9 and result["real_clips"] == 9
    assert "PFC" in result and "BeatAlign" not in result  # no music given
    # 9 clips a set, under the 20 of AIST++'s test set: said on stderr and in the JSON
    assert len(result["warnings"]) == 2 and "only 9 generated clips" in result["warnings"][0]
    err = printed.err
    assert "sm evaluate-dance: warning: only 9 generated clips: FID and Div need at least 20 per set" in err


def test_evaluate_dance_errors_name_the_file(folders, tmp_path, capsys):
    gen, real, music = folders
    assert sm_main(["evaluate-dance", str(tmp_path / "nope"), str(real)]) == 2
    assert "nope: no such folder" in capsys.readouterr().err
    bad = tmp_path / "bad"
    bad.mkdir()
    np.savez(bad / "x.npz", fps=30.0, skeleton="humanml3d22", joints=np.zeros((200, 22, 3)))
    assert sm_main(["evaluate-dance", str(bad), str(real), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "x.npz" in err and "SMPL-24" in err and "Traceback" not in err
    lonely = tmp_path / "lonely"
    lonely.mkdir()
    save_motion(lonely / "song.npz", MotionData(fps=60, joints=np.zeros((300, 24, 3), np.float32)))
    assert sm_main(["evaluate-dance", str(lonely), str(real), "--music-dir", str(music), "--quiet"]) == 2
    assert "song.npz: no music" in capsys.readouterr().err
