"""``sm export-web --ckpt CKPT --out site/``: the streaming dancer as a static page that dances in a browser.

Writes ``index.html``, ONE self-contained file that opens from disk (``file://``) or from any static server
and makes no network request, with the licences of what it embeds beside it:

- the dancer's :class:`~skeleton_mamba.tasks.stream.web_graph.WebStepGraph` (the causal music features of
  one 512-sample hop at 15360 Hz, the dancer's step, the joints) as one ONNX graph, base64;
- onnxruntime-web's wasm-only ES module and its wasm binary (:mod:`.ort_web`; the binary handed to it as
  ``env.wasm.wasmBinary``, so nothing is fetched), ``LICENSE-onnxruntime-web.txt``;
- three.js r170 and its OrbitControls as ``sm view`` embeds them
  (:mod:`skeleton_mamba.tasks.motion.render.viewer`), ``LICENSE-three.txt``.

The page (``web/dancer.html``) dances to a picked music file as it plays (decoded and resampled to 15360 Hz
by the browser) or to the microphone (an AudioWorklet at 15360 Hz), steps the graph once per hop with its
state fed back, draws the skeleton, and shows the step's time, the frames per second it allows and the
audio-to-pose latency. Its status line says what it waits for or does (before music: pick a file or press
the microphone button, with the dancer in its first pose on silence; decoding; preparing; dancing; a file
the browser cannot decode, said as such). A step does not yield the page's thread, so the page steps at
most 25 ms of frames (plus one) before it yields: where a machine steps slower than real time the dancer
falls behind (said on screen) and the page still answers. The wasm backend runs one thread from disk;
served cross-origin isolated (headers ``Cross-Origin-Opener-Policy: same-origin`` and
``Cross-Origin-Embedder-Policy: require-corp``) it takes ``?threads=N``. ``window.smDance`` exposes the
poses, joints, features and timings it computed, and the status (``status``, ``message``, ``statuses``).
"""

from __future__ import annotations

import base64
import html
import re
import tempfile
from collections.abc import Sequence
from importlib.resources import files
from pathlib import Path

import torch

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_folder, writing_outputs
from skeleton_mamba.tasks.motion.render.character import CHARACTER_SUFFIXES
from skeleton_mamba.tasks.motion.render.view import script_json, three_modules
from skeleton_mamba.tasks.motion.retarget.rig_output import RigOutput, prepare_rig
from skeleton_mamba.tasks.stream.export_web_args import build_parser
from skeleton_mamba.tasks.stream.features import FPS, HOP, SR
from skeleton_mamba.tasks.stream.model import StreamDancer
from skeleton_mamba.tasks.stream.module import StreamDanceModule
from skeleton_mamba.tasks.stream.ort_web import LICENCE_FILE, VERSION, OrtWeb, read_ort_web
from skeleton_mamba.tasks.stream.three_vrm import LICENCE_FILE as VRM_LICENCE_FILE
from skeleton_mamba.tasks.stream.three_vrm import ThreeVrm, read_three_vrm
from skeleton_mamba.tasks.stream.web_graph import check_web_dancer, web_step_spec
from skeleton_mamba.tasks.stream.web_quantize import PRECISIONS, quantization_tools, quantize_web_graph
from skeleton_mamba.tasks.training.onnx_export import export_onnx, max_difference_from_eager
from skeleton_mamba.tasks.training.pretrained import load_module_from

__all__ = ["PAGE", "THREE_LICENCE", "avatar_plan", "export_web_graph", "main", "write_page", "write_web_page"]

PAGE = "index.html"
THREE_LICENCE = "LICENSE-three.txt"


def _data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def export_web_graph(dancer: StreamDancer, path: Path) -> tuple[dict[str, list[int]], float]:
    """Write ``dancer``'s web graph to ``path``; its input shapes (but the audio) and onnxruntime's max
    |difference| from eager PyTorch on the example inputs."""
    spec = web_step_spec(dancer)
    export_onnx(spec, path)
    shapes = {n: list(a.shape) for n, a in zip(spec.input_names, spec.args) if n != "audio"}
    return shapes, max_difference_from_eager(spec, path)


def avatar_plan(rig: RigOutput) -> dict:
    """The plan by which the page drives ``rig`` from the dancer's SMPL-24 joints
    (:func:`~skeleton_mamba.tasks.motion.retarget.live.live_plan`, from SMPL's rest pose, feet on the
    floor)."""
    from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics  # lazy: with --rig only
    from skeleton_mamba.tasks.motion.retarget.live import live_plan  # lazy: with --rig only
    from skeleton_mamba.tasks.motion.retarget.rig import find_bones, separate_torso  # lazy: with --rig only

    eye = torch.eye(3, dtype=torch.float64).expand(len(SMPL24.parents), 3, 3)
    rest = smpl_forward_kinematics(eye, torch.zeros(3, dtype=torch.float64)).numpy()
    rest[:, 1] -= rest[:, 1].min()  # the feet on the floor
    bones, _ = find_bones(list(SMPL24.joint_names), "the dancer", what="motion")
    bones = separate_torso(bones, list(SMPL24.parents), rest[None])
    return live_plan(rig.rig, rest, bones)


def write_web_page(
    dancer: StreamDancer, out: str | Path, ort: OrtWeb, title: str, rig: RigOutput | None = None,
    vrm: ThreeVrm | None = None, quantize: str = "none",
) -> tuple[Path, float]:  # fmt: skip
    """Export ``dancer`` and write the page into the (claimed) folder ``out``; the page's path and the
    float32 graph's onnxruntime-vs-eager difference. ``quantize``: the graph's weights
    (:func:`~skeleton_mamba.tasks.stream.web_quantize.quantize_web_graph`: ``none``, ``int8``, ``int4``);
    the rest as :func:`write_page`."""
    with tempfile.TemporaryDirectory() as tmp:
        graph = Path(tmp) / "dancer.onnx"
        shapes, diff = export_web_graph(dancer, graph)
        if quantize != "none":
            graph = quantize_web_graph(graph, Path(tmp) / f"dancer.{quantize}.onnx", quantize)
        return write_page(graph, shapes, out, ort, title, rig, vrm, quantize), diff


def write_page(
    graph: Path, shapes: dict[str, list[int]], out: str | Path, ort: OrtWeb, title: str,
    rig: RigOutput | None = None, vrm: ThreeVrm | None = None, quantize: str = "none",
) -> Path:  # fmt: skip
    """Write the page of the web graph at ``graph`` (its input shapes but the audio: ``shapes``, as
    :func:`export_web_graph` returns them) into the (claimed) folder ``out``; the page's path. ``rig``: the
    character the page's dancer drives (its file embedded, and the plan of
    :func:`~skeleton_mamba.tasks.motion.retarget.live.live_plan`); ``vrm``: three-vrm, for a VRM character
    (its licence written beside the page); ``quantize``: how ``graph``'s weights were quantized, named by
    the page (``quantize`` and ``precision`` in its data; the precision on screen beside onnxruntime-web's
    version)."""
    out = Path(out)
    model = Path(graph).read_bytes()
    viewer, web = files("skeleton_mamba.tasks.motion.render.viewer"), files("skeleton_mamba.tasks.stream.web")
    data = {"title": title, "sr": SR, "hop": HOP, "fps": FPS, "parents": list(SMPL24.parents),
            "inputs": shapes, "ort_version": VERSION, "quantize": quantize, "precision": PRECISIONS[quantize],
            "avatar": None if rig is None else {**avatar_plan(rig), "vrm": vrm is not None}}  # fmt: skip
    fields = {
        "__TITLE__": html.escape(title),
        **three_modules(),
        "__ORT__": _data_uri(ort.module, "text/javascript"),
        "__DATA__": script_json(data),
        "__MODEL__": base64.b64encode(model).decode("ascii"),
        "__WASM__": base64.b64encode(ort.wasm).decode("ascii"),
        "__GLUE__": base64.b64encode(ort.glue).decode("ascii"),
        "__AVATAR_JS__": _data_uri(web.joinpath("avatar.js").read_bytes(), "text/javascript"),
        "__AVATAR__": "" if rig is None else base64.b64encode(rig.path.read_bytes()).decode("ascii"),
        "__VRM__": _data_uri(b"export {};" if vrm is None else vrm.module, "text/javascript"),
    }
    template = web.joinpath("dancer.html").read_text(encoding="utf-8")
    page = re.sub("|".join(fields), lambda match: fields[match.group()], template)
    with atomic_open(out / PAGE, "w", encoding="utf-8") as f:
        f.write(page)
    with atomic_open(out / LICENCE_FILE, "w", encoding="utf-8") as f:
        f.write(ort.licence)
    with atomic_open(out / THREE_LICENCE, "w", encoding="utf-8") as f:
        f.write(viewer.joinpath(THREE_LICENCE).read_text(encoding="utf-8"))
    if vrm is not None:
        with atomic_open(out / VRM_LICENCE_FILE, "w", encoding="utf-8") as f:
            f.write(vrm.licence)
    return out / PAGE


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm export-web``; returns 0 (bad input raises: ``sm`` prints one line, exit 2)."""
    args = build_parser().parse_args(list(argv) if argv is not None else None)
    suffix = None if args.rig is None else Path(args.rig).suffix.lower()
    vrm_rig = suffix == ".vrm"
    produced = [PAGE, LICENCE_FILE, THREE_LICENCE, *([VRM_LICENCE_FILE] if vrm_rig else [])]
    out = claim_output_folder(args.out, "sm export-web", produced, overwrite=args.overwrite)
    if suffix is not None and suffix not in CHARACTER_SUFFIXES:
        raise InputError(f"--rig {args.rig}: the page draws a character's mesh: a skinned .glb or .vrm")
    rig = prepare_rig(args, [out / name for name in produced], list(SMPL24.joint_names))  # before the model
    vrm = read_three_vrm(args.three_vrm) if vrm_rig else None  # a .vrm: drawn by three-vrm
    dancer = load_module_from(StreamDanceModule, args.ckpt).model.eval()
    check_web_dancer(dancer, f"--ckpt {args.ckpt}")  # before the onnxruntime-web tarball and the export
    if args.quantize != "none":
        quantization_tools(args.ckpt)  # before the export, as the tarball
    ort = read_ort_web(args.ort_web)  # checked before the export (a minute at the paper width)
    print("sm export-web: exporting the dancer's step with its music front end ...", flush=True)
    with writing_outputs(out, "sm export-web", produced, replaces=True):
        title = f"Skeleton Mamba dancer: {Path(args.ckpt).name}"
        page, diff = write_web_page(dancer, out, ort, title, rig, vrm, args.quantize)
    print(f"sm export-web: wrote {page} ({page.stat().st_size / 1e6:.1f} MB, {PRECISIONS[args.quantize]}; "
          f"fp32 graph: onnxruntime vs eager max |diff| {diff:.1e}); open it from disk or serve {out} "
          f"(python -m http.server -d {out})")  # fmt: skip
    return 0
