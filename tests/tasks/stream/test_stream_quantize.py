"""``sm stream --quantize int8``: the live dancer's Linear layers as PyTorch's dynamically quantized int8
Linear, through the frame path (:func:`skeleton_mamba.runtime.frame_ops.linear` calls the layer itself).

A small random causal dancer (D 64) streams a second of music eager in fp32 and quantized: every Linear is
replaced, and the joints stay within a measured tolerance of fp32's; ``sm stream`` records the option in
its report, and refuses it with ``--compile`` or ``--precision bf16`` and values other than none / int8.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
import torch
from torch import nn

from skeleton_mamba.tasks.motion.synthetic import synthesize_music, write_music
from skeleton_mamba.tasks.stream.features import HOP, SR
from skeleton_mamba.tasks.stream.live import LiveDancer
from skeleton_mamba.tasks.stream.model import tokens_to_motion
from skeleton_mamba.tasks.stream.module import StreamDanceModule
from skeleton_mamba.tasks.stream.stream_args import build_parser
from skeleton_mamba.tasks.stream.stream_cli import quantize_linear_int8
from skeleton_mamba.tasks.training.cli import main as sm
from tests.helpers.checkpoint_files import tiny_stream_checkpoint

SMALL = {"dim": 64, "depth": 1, "heads": 2, "mlp_dim": 256, "mixer": {"d_state": 16, "headdim": 16}}
# The joints' largest difference from fp32 over the second (m), about 2.2x the 22.6 mm measured on this dancer
# (mean 10.1 mm).
JOINTS_M = 0.05


def streamed_joints(model: nn.Module, audio: np.ndarray) -> np.ndarray:
    """The joints (T, 24, 3) ``model`` dances to ``audio`` (mono at SR) pushed one hop at a time."""
    with torch.inference_mode():
        dancer = LiveDancer(model, SR)
        for t in range(len(audio) // HOP):
            dancer.push(audio[t * HOP : (t + 1) * HOP])
        return tokens_to_motion(dancer.tokens()).joints


def test_the_int8_dancer_streams_near_the_fp32_one():
    torch.manual_seed(0)
    model = StreamDanceModule(backbone={**SMALL, "causal": True}, smoothing_stages=8).model.eval()
    linears = sum(isinstance(m, nn.Linear) for m in model.modules())
    quantized = quantize_linear_int8(copy.deepcopy(model))
    dynamic = torch.ao.nn.quantized.dynamic.Linear
    assert linears > 0 and sum(isinstance(m, dynamic) for m in quantized.modules()) == linears
    assert not any(type(m) is nn.Linear for m in quantized.modules())
    audio = synthesize_music(120.0, 1.0, sr=SR, seed=0).audio
    reference, ours = streamed_joints(model, audio), streamed_joints(quantized, audio)
    assert ours.shape == reference.shape == (30, 24, 3)
    error = np.linalg.norm(ours - reference, axis=-1)
    assert 0 < error.max() < JOINTS_M, error.max()


def test_sm_stream_records_int8_and_refuses_what_it_cannot_quantize(tmp_path, capsys):
    ckpt, _ = tiny_stream_checkpoint(tmp_path / "dancer.ckpt")
    wav = write_music(tmp_path / "song.wav", synthesize_music(120.0, 1.0, sr=22050, seed=3))
    base = ["stream", "--ckpt", str(ckpt), "--music", str(wav), "--no-render"]
    assert sm([*base, "--out", str(tmp_path / "live"), "--quantize", "int8"]) == 0
    report = json.loads((tmp_path / "live" / "song_stream.json").read_text())
    assert report["quantize"] == "int8" and report["frames"] == 30
    capsys.readouterr()
    for other in (["--compile"], ["--precision", "bf16"]):
        assert sm([*base, "--out", str(tmp_path / "refused"), "--quantize", "int8", *other]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--quantize int8 steps eager and in fp32" in err, err
    assert build_parser().parse_args(["--ckpt", "c", "--out", "o"]).quantize == "none"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--ckpt", "c", "--out", "o", "--quantize", "int4"])
