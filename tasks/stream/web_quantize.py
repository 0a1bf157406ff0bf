"""The web dancer's graph with quantized weights (``sm export-web --quantize``), by onnxruntime's own tools.

Only the weights of the dancer's ``nn.Linear`` layers are quantized: the ``MatMul`` nodes that the exporter
places in a ``linear`` scope of the step and whose second input is a constant matrix (96 % of the paper
width's weights; its few ``Gemm`` nodes, which neither tool quantizes, stay float32). The music front end's
filterbanks, the nearest-rotation and forward-kinematics products stay float32, as does every activation
that is not a quantized product's input.

- ``none``: the float32 graph as exported;
- ``int8``: :func:`onnxruntime.quantization.quantize_dynamic` of those ``MatMul`` weights, per output
  channel (``MatMulInteger``: int8 weights, each input quantized to uint8 as it is computed, one scale
  per tensor);
- ``int4``: :class:`onnxruntime.quantization.matmul_nbits_quantizer.MatMulNBitsQuantizer`, 4-bit weights in
  blocks of 32 along the input (``MatMulNBits``, accuracy level 4: the product in int8).
"""

from __future__ import annotations

import ast
import contextlib
import logging
from collections.abc import Iterator
from pathlib import Path

import onnx

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.atomic import atomic_path
from skeleton_mamba.tasks.stream.export_web_args import QUANTIZE_CHOICES

__all__ = [
    "PRECISIONS",
    "QUANTIZE_CHOICES",
    "linear_weight_nodes",
    "quantization_tools",
    "quantize_web_graph",
]

PRECISIONS = {
    "none": "fp32 weights",
    "int8": "int8 weights (MatMulInteger, per channel)",
    "int4": "int4 weights (MatMulNBits, blocks of 32)",
}
BLOCK = 32  # int4: weights per scale along the input
ACCURACY_LEVEL = 4  # MatMulNBits: the activations quantized to int8 for the product


def _scopes(node: onnx.NodeProto) -> list[str]:
    """The exporter's module scopes of ``node`` (``pkg.torch.onnx.name_scopes``; empty when absent)."""
    for prop in node.metadata_props:
        if prop.key == "pkg.torch.onnx.name_scopes":
            return ast.literal_eval(prop.value)
    return []


def linear_weight_nodes(model: onnx.ModelProto) -> list[str]:
    """The names of the ``MatMul`` nodes of ``model`` that apply a step's ``nn.Linear`` to a constant 2-D
    weight (the exporter's name scope ``step``, then one ``linear*`` op), in graph order."""
    matrices = {i.name for i in model.graph.initializer if len(i.dims) == 2}
    names = []
    for node in model.graph.node:
        scopes = _scopes(node)
        if (
            node.op_type == "MatMul"
            and node.input[1] in matrices
            and scopes[1:2] == ["step"]
            and scopes[-1].startswith("linear")
        ):
            names.append(node.name)
    return names


@contextlib.contextmanager
def _root_logging_kept(level: int | None = None) -> Iterator[None]:
    """Restore the root logger's handlers and level after the block; ``level``: the root level inside it.

    Importing ``matmul_nbits_quantizer`` calls ``logging.basicConfig(level=INFO)`` (every INFO record of
    the process would then print), and the quantizers log each node and advise pre-processing."""
    root = logging.getLogger()
    handlers, kept = list(root.handlers), root.level
    if level is not None:
        root.setLevel(level)
    try:
        yield
    finally:
        root.handlers[:] = handlers
        root.setLevel(kept)


def quantization_tools(source: str | Path):
    """``onnxruntime.quantization`` and its ``matmul_nbits_quantizer`` (they ship with onnxruntime), else
    an :class:`InputError` naming ``source``."""
    try:
        with _root_logging_kept():
            from onnxruntime import quantization  # lazy: only sm export-web --quantize needs it
            from onnxruntime.quantization import matmul_nbits_quantizer  # lazy: as above
    except ImportError as err:
        raise InputError(
            f"{source}: quantizing the web graph needs onnxruntime's quantization tools "
            f"(onnxruntime.quantization: {err}); install onnxruntime (pip install onnxruntime) or export "
            "with --quantize none"
        ) from err
    return quantization, matmul_nbits_quantizer


def quantize_web_graph(source: str | Path, target: str | Path, quantize: str) -> Path:
    """Write the web graph at ``source`` with its Linear weights quantized (``quantize``: one of
    :data:`QUANTIZE_CHOICES` but ``none``; module docstring) to ``target``, atomically.

    The graph's inputs and outputs keep their names, shapes (``audio`` (1, 512), the states, ``pose``
    (1, 24, 12), ``joints`` (1, 24, 3), ...) and float32 type.

    Raises:
        InputError: naming ``source`` when onnxruntime's quantization tools are missing.
        ValueError: for another ``quantize``.
    """
    if quantize not in QUANTIZE_CHOICES[1:]:
        raise ValueError(f"quantize: one of {QUANTIZE_CHOICES[1:]}, not {quantize!r}")
    source, target = Path(source), Path(target)
    quantization, nbits = quantization_tools(source)
    model = onnx.load(source)
    nodes = linear_weight_nodes(model)
    if not nodes:
        raise InputError(
            f"{source}: no Linear weight found to quantize (the exporter's name scopes are missing)"
        )
    others = [n.name for n in model.graph.node if n.op_type == "MatMul" and n.name not in set(nodes)]
    with atomic_path(target) as tmp, _root_logging_kept(logging.ERROR):
        if quantize == "int8":
            quantization.quantize_dynamic(
                model, tmp, op_types_to_quantize=["MatMul"], per_channel=True, nodes_to_quantize=nodes,
                weight_type=quantization.QuantType.QInt8,
            )  # fmt: skip
        else:
            quantizer = nbits.MatMulNBitsQuantizer(
                model, bits=4, block_size=BLOCK, is_symmetric=True, accuracy_level=ACCURACY_LEVEL,
                nodes_to_exclude=others,
            )  # fmt: skip
            quantizer.process()
            quantizer.model.save_model_to_file(str(tmp))
    return target
