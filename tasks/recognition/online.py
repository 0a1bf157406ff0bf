"""Online action recognition: class probabilities after every frame of a skeleton stream.

A causal recognizer (``recognition_synthetic_causal.yaml`` or any recognition recipe with
``backbone.causal: true``) runs frame by frame: one :meth:`SkeletonMamba.step` per body and frame,
a running mean of the joint-averaged features per body, then the linear head over the bodies seen
so far. This is :func:`skeleton_mamba.tasks.recognition.early.online_probabilities` computed
incrementally, in constant memory.

``sm stream --task recognition --ckpt CKPT --skeleton FILE --out DIR`` (:func:`main`) reads a raw NTU RGB+D
``.skeleton`` file (its bodies chosen as ``sm prepare`` does, then normalised as the recipes' pipeline does:
PYSKL ``PreNormalize3D``, :func:`~.transforms.pre_normalize_3d`) or a ``.npy`` of keypoints in the network's
input convention (as the recipe's data pipeline hands them to the model: (T, J, C) for one body or
(M, T, J, C)), feeds them frame by frame, and writes ``DIR/<name>_online.csv`` (frame,
top class, probability of each class), ``DIR/<name>_online.png`` (probabilities over time) and
prints the top class after the last frame.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.errors import InputError, one_line_message
from skeleton_mamba.io.atomic import atomic_open, atomic_path
from skeleton_mamba.runtime.compiling import compile_step_or_eager
from skeleton_mamba.ssd.precision import inference_precision
from skeleton_mamba.tasks.motion.formats.ntu import read_skeleton_file
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_folder, writing_outputs
from skeleton_mamba.tasks.motion.io.value_checks import load_npy
from skeleton_mamba.tasks.recognition.model import ActionRecognizer, pool_bodies
from skeleton_mamba.tasks.recognition.module import ActionRecognitionModule
from skeleton_mamba.tasks.recognition.online_args import build_parser
from skeleton_mamba.tasks.recognition.transforms import pre_normalize_3d, skeleton_features
from skeleton_mamba.tasks.training.frame_timing import (
    announce_compile,
    latency_summary,
    prepare_live,
    report_compile,
)
from skeleton_mamba.tasks.training.pretrained import load_module_and_checkpoint_from

__all__ = ["OnlineRecognizer", "build_parser", "main", "stream_recognition"]


class OnlineRecognizer:
    """Per-frame class probabilities of a causal :class:`ActionRecognizer`, ``batch`` streams of M bodies.

    ``compile``: step the backbone through ``torch.compile`` (:mod:`skeleton_mamba.runtime.compiling`),
    compiled here; if compiling fails, a warning and the eager step (``compile_seconds``: None).
    """

    def __init__(
        self, model: ActionRecognizer, batch: int = 1, bodies: int = 1, compile: bool = False
    ) -> None:
        if not model.backbone.config.causal:
            raise ValueError("online recognition needs a causal backbone (backbone.causal: true)")
        self.model = model.eval()
        self.backbone_step, self.compile_seconds = model.backbone.step, None
        if compile:
            self.backbone_step, self.compile_seconds = compile_step_or_eager(model.backbone, batch * bodies)
        self.batch, self.bodies = batch, bodies
        self.state = model.backbone.init_state(batch * bodies)
        width = model.backbone.out_channels
        weight = next(model.parameters())
        self.feature_sum = torch.zeros(batch, bodies, width, dtype=weight.dtype)
        self.present = torch.zeros(batch, bodies, dtype=torch.bool)
        self.frames = 0

    @torch.inference_mode()
    def push(self, frame: torch.Tensor) -> torch.Tensor:
        """One frame (B, M, J, C) -> class probabilities (B, K) from every frame so far."""
        b, m = frame.shape[:2]
        if (b, m) != (self.batch, self.bodies):
            expected = f"({self.batch}, {self.bodies}, J, C)"
            raise ValueError(f"expected a frame of {expected}, got {tuple(frame.shape)}")
        y, self.state = self.backbone_step(
            self.model.normalize(frame).flatten(0, 1), self.state
        )  # (B*M, J, D)
        self.feature_sum += y.mean(dim=1).view(b, m, -1)
        self.present |= frame.flatten(2).ne(0).any(dim=-1)
        self.frames += 1
        logits = self.model.head(pool_bodies(self.feature_sum / self.frames, self.present))
        # at least fp32 probabilities (also under bf16 autocast); a float64 model keeps float64
        return logits.softmax(dim=-1, dtype=torch.promote_types(logits.dtype, torch.float32))


def _load_keypoints(path: Path) -> np.ndarray:
    """(M, T, J, C) float32 keypoints from an NTU ``.skeleton`` (normalised as the recipes' pipeline) or a
    ``.npy`` of (T, J, C) or (M, T, J, C) (already in the network's input convention)."""
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".skeleton"):
        raise ValueError(
            f"{path}: expected an NTU .skeleton file or a .npy of keypoints (T, J, C) or (M, T, J, C)"
        )
    if not path.is_file():
        raise FileNotFoundError(f"{path}: skeleton file not found")
    if suffix == ".skeleton":
        raw = read_skeleton_file(path).keypoints(max_bodies=2)  # (M, T, 25, 3), bodies as sm prepare
        if raw.shape[1] == 0:
            raise ValueError(f"{path}: no frame lists a body")
        return pre_normalize_3d(raw).astype(np.float32)
    x = load_npy(path)
    if x.ndim == 3:
        x = x[None]
    if x.ndim != 4:
        raise ValueError(f"{path}: expected keypoints (T, J, C) or (M, T, J, C), got shape {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError(f"{path}: keypoints hold NaN or Inf")
    return x.astype(np.float32)


COMMAND = "sm stream --task recognition"


def _plot(prob: np.ndarray, names: list[str], path: Path) -> None:
    import matplotlib  # lazy: matplotlib only for this figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib only for this figure

    fig, ax = plt.subplots(figsize=(6, 3.5), dpi=120)
    for k in np.argsort(-prob.max(axis=0))[:5]:
        ax.plot(np.arange(1, len(prob) + 1), prob[:, k], label=names[k])
    ax.set(xlabel="frames seen", ylabel="probability", ylim=(0, 1.02), title="Online recognition")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """``sm stream --task recognition`` (see the module docstring); returns the exit code."""
    args = build_parser().parse_args(argv)
    prepare_live(args.ckpt, args.threads)
    try:
        return stream_recognition(args)
    except ValueError as err:  # the keypoint readers' checks name the file: one line, exit 2
        raise InputError(one_line_message(err)) from err


def _stream_features(joints: np.ndarray, checkpoint: dict, skeleton: str, ckpt: str) -> np.ndarray:
    """The input stream the checkpoint was trained on (its data's ``feats``, [PYSKL] ``GenSkeFeat``) of
    ``joints`` (M, T, J, C), frame by frame: joints and bones need only the frame itself; a motion stream
    needs the next frame, which a live recognizer does not have yet, and is refused."""
    data = checkpoint.get("datamodule_hyper_parameters")
    feats = tuple((data.get("feats") if isinstance(data, dict) else None) or ("j",))
    if any(f in ("jm", "bm") for f in feats):
        raise ValueError(
            f"{ckpt}: trained on feats {list(feats)}; a motion stream needs the next frame, which sm stream "
            "does not have yet: stream a joint or bone checkpoint (feats [j] or [b])"
        )
    return skeleton_features(joints, feats, skeleton).astype(np.float32)


def stream_recognition(args: argparse.Namespace) -> int:
    """Feed ``args.skeleton`` frame by frame to the checkpoint's recognizer; write the table and the plot."""
    path = Path(args.skeleton)
    name = args.name or path.stem
    produced = [f"{name}_online.csv", f"{name}_online.png"]
    claim_output_folder(args.out, COMMAND, produced, overwrite=args.overwrite)
    joints = _load_keypoints(path)
    module, checkpoint = load_module_and_checkpoint_from(ActionRecognitionModule, args.ckpt)
    model = module.model
    keypoints = _stream_features(joints, checkpoint, model.backbone.skeleton.name, args.ckpt)
    m, t, j, c = keypoints.shape
    expected = (model.backbone.skeleton.num_joints, model.backbone.config.in_channels)
    if (j, c) != expected:
        raise ValueError(f"{path}: keypoints have (J, C) = {(j, c)}, the model reads {expected}")
    names = list(module.hparams.get("class_names") or [str(k) for k in range(model.head.out_features)])
    if args.compile and args.precision != "fp32":
        raise ValueError(f"--compile steps in fp32 only: drop --compile or --precision {args.precision}")
    online = OnlineRecognizer(model, 1, m, compile=announce_compile(args.compile))
    report_compile(online.compile_seconds, args.compile)
    frames = torch.from_numpy(keypoints).permute(1, 0, 2, 3)[:, None]  # (T, 1, M, J, C)
    probs, latency = [], []
    with inference_precision(args.precision):
        for frame in frames:
            start = time.perf_counter()
            probs.append(online.push(frame)[0].numpy())
            latency.append(1e3 * (time.perf_counter() - start))
    prob = np.stack(probs)
    with writing_outputs(args.out, COMMAND, produced) as out:
        table = out / f"{name}_online.csv"
        with atomic_open(table, "w", newline="", encoding="utf-8") as f:
            writer = csv.writer(f)
            writer.writerow(["frame", "top_class", *names])
            for i, row in enumerate(prob):
                writer.writerow([i, names[int(row.argmax())], *(f"{v:.6f}" for v in row)])
        _plot(prob, names, out / f"{name}_online.png")
    top = int(prob[-1].argmax())
    first = int(np.argmax(prob.argmax(axis=1) == top))
    lat = latency_summary(np.asarray(latency))
    print(f"sm stream: {t} frames, {m} bod{'y' if m == 1 else 'ies'}; after the last frame: {names[top]} "
          f"(p = {prob[-1, top]:.3f}; first ranked top at frame {first})")  # fmt: skip
    print(f"  {table}\n  {out / f'{name}_online.png'}")
    print(f"  per-frame time: median {lat['median_ms']:.2f} ms, p99 {lat['p99_ms']:.2f} ms")
    return 0
