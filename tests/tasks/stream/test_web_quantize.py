"""``sm export-web --quantize``: the web graph with its Linear weights quantized by onnxruntime's tools.

A small random causal dancer (D 64, its Linear weights most of the graph's bytes) exported once: the int8
and int4 graphs load in onnxruntime, quantize the step's Linear layers only, are smaller than the float32
graph, and their joints stay within a measured tolerance of the float32 graph's over a second of music,
each frame stepped from the float32 graph's state and over the whole stream; the option refuses unknown
values; the page names its precision; missing tools are said in one line naming the file.
"""

from __future__ import annotations

import json
import re
import sys

import numpy as np
import onnx
import onnxruntime
import pytest
import torch

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.motion.synthetic import synthesize_music
from skeleton_mamba.tasks.stream.export_web_args import build_parser
from skeleton_mamba.tasks.stream.features import SR
from skeleton_mamba.tasks.stream.module import StreamDanceModule
from skeleton_mamba.tasks.stream.web_export import PAGE, export_web_graph
from skeleton_mamba.tasks.stream.web_graph import run_web_graph
from skeleton_mamba.tasks.stream.web_quantize import PRECISIONS, linear_weight_nodes, quantize_web_graph
from skeleton_mamba.tasks.training.cli import main as sm
from tests.helpers.browser_page import ort_web_or_skip
from tests.helpers.checkpoint_files import save_module_checkpoint, tiny_stream_checkpoint

SMALL = {"dim": 64, "depth": 1, "heads": 2, "mlp_dim": 256, "mixer": {"d_state": 16, "headdim": 16}}
# The joints' largest difference from the float32 graph (m), a frame stepped from the same state / over the
# whole second, about 1.7x what was measured on this dancer (int8 14.6 / 14.6 mm, int4 171 / 187 mm: the
# first frame's, which the 8-stage low-pass passes whole; a random dancer's rotations are far from any
# rotation, so their projection magnifies the weights' error)
ONE_STEP_M = {"int8": 0.025, "int4": 0.3}
WHOLE_M = {"int8": 0.025, "int4": 0.3}


@pytest.fixture(scope="module")
def graphs(tmp_path_factory):
    """The small dancer, its float32 web graph and the int8 and int4 graphs."""
    tmp = tmp_path_factory.mktemp("web_quantize")
    torch.manual_seed(0)
    dancer = StreamDanceModule(backbone={**SMALL, "causal": True}, smoothing_stages=8).model.eval()
    fp32 = tmp / "dancer.onnx"
    export_web_graph(dancer, fp32)
    quantized = {q: quantize_web_graph(fp32, tmp / f"dancer.{q}.onnx", q) for q in ("int8", "int4")}
    return dancer, fp32, quantized


def test_only_the_steps_linear_weights_are_quantized_and_the_graph_shrinks(graphs):
    _, fp32, quantized = graphs
    model = onnx.load(fp32)
    linear = linear_weight_nodes(model)
    weights = {i.name: i for i in model.graph.initializer}
    matmuls = {n.name: n for n in model.graph.node if n.op_type == "MatMul"}
    assert linear and all(matmuls[n].input[1] in weights for n in linear)
    linear_bytes = sum(4 * int(np.prod(weights[matmuls[n].input[1]].dims)) for n in linear)
    assert linear_bytes > 0.5 * fp32.stat().st_size  # a width where the Linear weights dominate
    for q, op in (("int8", "MatMulInteger"), ("int4", "MatMulNBits")):
        ops = [n.op_type for n in onnx.load(quantized[q]).graph.node]
        assert ops.count(op) == len(linear), (q, ops.count(op), len(linear))
        # the front end's filterbanks and the joints' products stay float32 MatMuls
        assert ops.count("MatMul") >= len(matmuls) - len(linear)
    sizes = {q: path.stat().st_size for q, path in {"none": fp32, **quantized}.items()}
    assert sizes["int8"] < fp32.stat().st_size - 0.6 * linear_bytes, sizes  # int8: a quarter of the weights
    assert sizes["int4"] < sizes["int8"], sizes


@pytest.mark.parametrize("quantize", ["int8", "int4"])
def test_the_quantized_graph_steps_near_the_float32_graph(graphs, quantize):
    dancer, fp32, quantized = graphs
    session = onnxruntime.InferenceSession(str(quantized[quantize]), providers=["CPUExecutionProvider"])
    assert [o.name for o in session.get_outputs()][:3] == ["pose", "joints", "features"]
    audio = synthesize_music(120.0, 1.0, sr=SR, seed=0).audio
    reference = run_web_graph(fp32, dancer, audio, beside=quantized[quantize])
    ours = run_web_graph(quantized[quantize], dancer, audio)
    assert len(ours["joints"]) == len(reference["joints"]) == 30
    np.testing.assert_allclose(ours["features"], reference["features"], rtol=0, atol=1e-5)  # not quantized
    one_step = np.abs(reference["beside_joints"] - reference["joints"]).max()
    whole = np.abs(ours["joints"] - reference["joints"]).max()
    assert 0 < one_step < ONE_STEP_M[quantize], one_step
    assert whole < WHOLE_M[quantize], whole


def test_the_option_is_parsed_and_refuses_other_values(capsys):
    base = ["--ckpt", "dancer.ckpt", "--out", "site"]
    assert build_parser().parse_args(base).quantize == "none"
    for q in ("none", "int8", "int4"):
        assert build_parser().parse_args([*base, "--quantize", q]).quantize == q
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args([*base, "--quantize", "int3"])
    assert exit_.value.code == 2 and "invalid choice: 'int3'" in capsys.readouterr().err
    with pytest.raises(ValueError, match="int3"):
        quantize_web_graph("dancer.onnx", "out.onnx", "int3")


def page_data(page) -> dict:
    """The page's data (``DATA``: title, shapes, precision, ...)."""
    text = page.read_text(encoding="utf-8")
    return json.loads(
        re.search(r'<script id="sm-data" type="application/json">(.*?)</script>', text, re.S)[1]
    )


def test_the_page_names_its_precision(tmp_path, capsys):
    ort_web_or_skip()
    ckpt, _ = tiny_stream_checkpoint(tmp_path / "dancer.ckpt")
    assert sm(["export-web", "--ckpt", str(ckpt), "--out", str(tmp_path / "site"), "--quantize", "int8"]) == 0
    data = page_data(tmp_path / "site" / PAGE)
    assert data["quantize"] == "int8" and data["precision"] == PRECISIONS["int8"]
    assert PRECISIONS["int8"] in capsys.readouterr().out
    assert not list((tmp_path / "site").glob(".index*")), list((tmp_path / "site").iterdir())  # no temporary


def test_missing_quantization_tools_are_said_naming_the_file(graphs, tmp_path, monkeypatch):
    _, fp32, _ = graphs
    monkeypatch.setitem(sys.modules, "onnxruntime.quantization", None)  # import fails
    with pytest.raises(InputError, match=rf"{re.escape(str(fp32))}: .*onnxruntime's quantization tools"):
        quantize_web_graph(fp32, tmp_path / "out.onnx", "int8")
    assert not (tmp_path / "out.onnx").exists()


def test_sm_export_web_says_missing_tools_before_the_export(tmp_path, capsys, monkeypatch):
    tiny = {"dim": 16, "depth": 1, "heads": 2, "mlp_dim": 32, "mixer": {"d_state": 16, "headdim": 8}}
    ckpt = save_module_checkpoint(StreamDanceModule(backbone={**tiny, "causal": True}), tmp_path / "d.ckpt")
    monkeypatch.setitem(sys.modules, "onnxruntime.quantization", None)
    out = tmp_path / "site"
    assert sm(["export-web", "--ckpt", str(ckpt), "--out", str(out), "--quantize", "int4"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(ckpt) in err and "quantization tools" in err, err
    assert not (out / PAGE).exists()
