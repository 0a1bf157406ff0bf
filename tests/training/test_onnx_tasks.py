"""ONNX and torch.export of the task networks: the streaming dancer, recognition, EMM, text-to-motion.

Each graph is exported strictly (``torch.export.export(strict=True)``), converted to ONNX and run in
onnxruntime; both are compared with the eager PyTorch network (an independent execution: onnxruntime's
kernels, and the ATen graph torch.export traced) at two lengths, with padding masks where the network
takes them. The dancer's step graph, stepped frame by frame, is compared with the eager teacher-forced
sequence forward. Tiny random networks; strict tracing takes about half a minute a graph on 2 cores, so
the default run exports the dancer's step and the recognition network, the others run under ``-m slow``.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
from skeleton_mamba.tasks.egodance.onnx_graphs import emm_specs
from skeleton_mamba.tasks.recognition.model import ActionRecognizer
from skeleton_mamba.tasks.recognition.onnx_graphs import recognizer_specs
from skeleton_mamba.tasks.stream.model import StreamDancer
from skeleton_mamba.tasks.stream.onnx_graphs import dancer_specs
from skeleton_mamba.tasks.text2motion.model import TextCondition, TextToMotionDenoiser
from skeleton_mamba.tasks.text2motion.onnx_graphs import text_denoiser_specs
from skeleton_mamba.tasks.training import onnx_export
from skeleton_mamba.tasks.training.cli import main as sm

TOL = 1e-4  # fp32, max abs difference
MIXER = MixerConfig(d_state=8, headdim=8, chunk_size=16)
TINY = SkeletonMambaConfig(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MIXER)


def exported(spec: onnx_export.ExportSpec, path):
    program = onnx_export.export_program(spec, strict=True)
    return program, onnx_export.export_onnx(spec, path, program)


def mask(batch: int, frames: int) -> torch.Tensor:
    m = torch.ones(batch, frames, dtype=torch.bool)
    m[-1, frames - frames // 3 :] = False
    return m


def assert_matches(path, program, names, inputs, eager_fn) -> None:
    with torch.no_grad():
        eager = eager_fn(*inputs)
        traced = program.module()(*inputs)
    (ours,) = onnx_export.run_onnx(path, dict(zip(names, inputs)))
    assert ours.shape == tuple(eager.shape)
    assert np.abs(ours - eager.numpy()).max() <= TOL
    assert (traced - eager).abs().max() <= TOL


def dancer(smoothing_stages: int = 0) -> StreamDancer:
    torch.manual_seed(0)
    model = StreamDancer(TINY, music_dim=6, smoothing_stages=smoothing_stages)
    model.set_music_statistics(torch.randn(40, 6) * 5 + 2)  # the standardisation is inside the graphs
    return model.eval()


@pytest.mark.slow
def test_dancer_sequence_graph_matches_eager(tmp_path):
    model = dancer()
    spec = dancer_specs(model, frames=12)["sequence"]
    program, path = exported(spec, tmp_path / "sequence.onnx")
    for batch, frames in ((2, 12), (3, 37)):
        inputs = (torch.randn(batch, frames, 24, 12), torch.randn(batch, frames, 6) * 5)
        assert_matches(path, program, spec.input_names, inputs, model)


@pytest.mark.parametrize("smoothing_stages", [0, 3])
def test_dancer_step_graph_stepped_equals_the_teacher_forced_forward(tmp_path, smoothing_stages):
    model = dancer(smoothing_stages)
    spec = dancer_specs(model)["step"]
    assert spec.input_names[:2] == ["prev", "music"] and spec.output_names[0] == "pose"
    program, path = exported(spec, tmp_path / "step.onnx")
    batch, frames = 3, 60
    prev, music = torch.randn(batch, frames, 24, 12), torch.randn(batch, frames, 6) * 5
    with torch.no_grad():
        full = model(prev, music)  # eager, the whole sequence at once
    states = onnx_export.zero_states(model.backbone, batch)
    if smoothing_stages:  # started = 0 at the first frame: the low-pass's stages are then ignored
        assert spec.input_names[2:4] == ["started", "smoothing"] and spec.output_names[1] == "next_smoothing"
        states = [torch.zeros(()), torch.full((smoothing_stages, batch, 24, 12), 7.0), *states]
    traced_states = list(states)
    worst = traced_worst = 0.0
    with torch.no_grad():
        for t in range(frames):
            if smoothing_stages and t == 1:
                states[0] = traced_states[0] = torch.ones(())
            feeds = dict(zip(spec.input_names, [prev[:, t], music[:, t], *states]))
            pose, *nxt = onnx_export.run_onnx(path, feeds)
            states = [*states[:1]] * bool(smoothing_stages) + [torch.from_numpy(s) for s in nxt]
            worst = max(worst, float(np.abs(pose - full[:, t].numpy()).max()))
            if t < 10:
                pose_t, *nxt_t = program.module()(prev[:, t], music[:, t], *traced_states)
                traced_states = [*traced_states[:1]] * bool(smoothing_stages) + nxt_t
                traced_worst = max(traced_worst, float((pose_t - full[:, t]).abs().max()))
    assert worst <= TOL
    assert traced_worst <= TOL


def test_recognition_graph_matches_eager_with_absent_bodies(tmp_path):
    torch.manual_seed(0)
    ntu = SkeletonMambaConfig(
        skeleton="ntu25", in_channels=3, dim=16, depth=1, heads=2, mlp_dim=32, mixer=MIXER
    )
    model = ActionRecognizer(ntu, num_classes=5).eval()
    spec = recognizer_specs(model, frames=12)["sequence"]
    program, path = exported(spec, tmp_path / "sequence.onnx")
    for batch, bodies, frames in ((2, 2, 12), (3, 1, 41), (3, 2, 30)):
        x = torch.randn(batch, bodies, frames, 25, 3)
        x[0, 1:] = 0.0  # an absent body (zeros): left out of the mean over bodies
        assert_matches(path, program, ["x"], (x,), model)


@pytest.mark.slow
def test_emm_denoiser_graph_matches_eager_with_padding(tmp_path):
    torch.manual_seed(0)
    model = EMM(
        TINY, EMMConfig(context_dim=16, use_vision=False, heads=2, transformer_ff=32), diffusion_steps=20
    )
    model.set_data_statistics(torch.randn(2, 8, 24, 10) * 3 + 1)
    spec = emm_specs(model.eval(), frames=12)["denoiser"]
    program, path = exported(spec, tmp_path / "denoiser.onnx")
    for batch, frames, tokens in ((2, 12, 7), (3, 33, 33)):
        inputs = (torch.randn(batch, frames, 24, 10), torch.randint(0, 20, (batch,)),
                  torch.randn(batch, tokens, 16), mask(batch, frames))  # fmt: skip
        assert_matches(path, program, spec.input_names, inputs, model)


@pytest.mark.slow
@pytest.mark.parametrize("temporal_prior", [False, True])
def test_text_denoiser_graph_matches_eager_with_padding(tmp_path, temporal_prior):
    torch.manual_seed(0)
    model = TextToMotionDenoiser(
        TINY, text_dim=12, time_channels=4, time_embedding_dim=16, diffusion_steps=20,
        temporal_prior=temporal_prior,
    )  # fmt: skip
    model.set_data_statistics(torch.randn(200, 263) * 2, torch.tensor([120, 80]))
    spec = text_denoiser_specs(model.eval(), frames=12)["denoiser"]
    program, path = exported(spec, tmp_path / "denoiser.onnx")

    def eager(x_t, t, text, text_mask, frame_mask):  # the denoiser as the samplers call it
        return model(x_t, t, TextCondition(text, text_mask), frame_mask)

    for batch, frames, words in ((2, 12, 7), (3, 29, 4)):
        x_t, t = torch.randn(batch, frames, 263), torch.randint(0, 20, (batch,))
        inputs = (x_t, t, torch.randn(batch, words, 12), mask(batch, words), mask(batch, frames))
        assert_matches(path, program, spec.input_names, inputs, eager)


@pytest.mark.slow
def test_export_onnx_command_writes_a_pretrained_recognizer(tmp_path, capsys):
    torch.manual_seed(0)
    ntu = SkeletonMambaConfig(
        skeleton="ntu25", in_channels=3, dim=16, depth=1, heads=2, mlp_dim=32, mixer=MIXER
    )
    model = ActionRecognizer(ntu, num_classes=5).eval()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.save_pretrained(tmp_path / "pretrained")
    out = tmp_path / "onnx"
    assert (
        sm(["export-onnx", "--pretrained", str(tmp_path / "pretrained"), "--out", str(out), "--check"]) == 0
    )
    record = json.loads((out / "export.json").read_text())
    assert record["network"] == "ActionRecognizer" and list(record["graphs"]) == ["sequence"]
    assert record["graphs"]["sequence"]["max_abs_diff_vs_eager"] <= TOL
    x = torch.randn(1, 2, 17, 25, 3)
    with torch.no_grad():
        eager = model(x)
    (ours,) = onnx_export.run_onnx(out / "sequence.onnx", {"x": x})
    assert np.abs(ours - eager.numpy()).max() <= TOL
