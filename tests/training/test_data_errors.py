"""Training-data errors of the data modules are the project's error types, so ``sm`` prints them as one line
(exit 2) instead of a traceback: windows that fit no sequence, malformed caption and split files."""

from __future__ import annotations

import pytest
import torch

from skeleton_mamba.errors import DataFileError, SkeletonMambaError, expected_failure
from skeleton_mamba.tasks.qean.data import DanceWindowDataset
from skeleton_mamba.tasks.stream.data import WindowDataset
from skeleton_mamba.tasks.text2motion.humanml3d import read_captions, read_split

SHORT = {"a": (torch.zeros(10, 24, 12), torch.zeros(10, 34))}  # 10 frames of motion and music


def test_no_stream_window_fits():
    message = r"no sequence holds a window of 20 frames \(1 sequences\)"
    with pytest.raises(DataFileError, match=message) as err:
        WindowDataset(SHORT, window=20, stride=1)
    assert expected_failure(err.value) is err.value


def test_no_qean_window_fits():
    message = r"every sequence needs >= 15 motion frames and >= 12 music frames"
    with pytest.raises(DataFileError, match=message):
        DanceWindowDataset(SHORT, seed_frames=10, music_frames=12, predict_frames=5, stride=1)


def test_malformed_humanml3d_files_name_file_and_line(tmp_path):
    (tmp_path / "train.txt").write_text("000001\nnot-an-id\n")
    with pytest.raises(DataFileError, match=r"train\.txt:2: malformed HumanML3D id 'not-an-id'"):
        read_split(tmp_path, "train")
    (tmp_path / "texts").mkdir()
    (tmp_path / "texts" / "000001.txt").write_text("a person walks#a/DET#0.0\n")
    with pytest.raises(DataFileError, match=r"000001\.txt:1: want 'caption#tokens#start#end', got 3 fields"):
        read_captions(tmp_path, "000001")
    (tmp_path / "texts" / "000001.txt").write_text("a person walks#a/DET#zero#1.0\n")
    with pytest.raises(SkeletonMambaError, match=r"start/end are not numbers: 'zero', '1.0'"):
        read_captions(tmp_path, "000001")
