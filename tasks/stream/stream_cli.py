"""``sm stream``: run a causal Skeleton Mamba frame by frame on a live input.

Examples::

    sm stream --ckpt runs/stream_dance_demo/version_0/checkpoints/last.ckpt --music song.wav --out live/
    sm stream --ckpt last.ckpt --music song.wav --out live/ --realtime          # paced like live music
    arecord -f S16_LE -r 44100 -c 1 -t wav | sm stream --ckpt last.ckpt --music - --out live/
    sox song.mp3 -t raw -r 22050 -e signed -b 16 -c 1 - \\
        | sm stream --ckpt last.ckpt --music - --raw-rate 22050 --out live/
    sm stream --ckpt last.ckpt --music song.wav --out live/ --compile     # torch.compile the frame step first
    sm stream --task recognition --ckpt best.ckpt --skeleton S001C001P001R001A001.skeleton --out online/

Dance (``--task dance``, default): reads the music in chunks of ``--chunk-ms`` as it arrives, extracts
causal features (:mod:`skeleton_mamba.tasks.stream.features`: no look-ahead; a pose frame needs
its own 33.3 ms of audio) and emits one pose per 30 fps frame. At the end (or on Ctrl-C) it writes
``DIR/<name>.npz`` (our motion format), ``<name>.bvh``, ``<name>.mp4`` (the skeleton with the music),
with ``--rig RIG`` (``--map``) ``<name>_rig.glb`` / ``.vrm`` / ``.bvh`` (the dance on that character)
and ``<name>_stream.json`` (frame count, latency figures, file paths), and prints
the audio-to-pose latency: median / p99 / max over frames of the time from the delivery of the audio
chunk that completes a frame to its pose.

Recognition (``--task recognition``): see :mod:`skeleton_mamba.tasks.recognition.online`.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import soundfile as sf
import torch
from torch import nn

from skeleton_mamba.errors import InputError, one_line_message
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.ssd.precision import inference_precision
from skeleton_mamba.tasks.motion.formats.export import dance_files, write_motion
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_folder, writing_outputs
from skeleton_mamba.tasks.motion.render.skeleton import RenderStyle
from skeleton_mamba.tasks.motion.retarget.rig_output import RigOutput, prepare_rig, rig_file_names
from skeleton_mamba.tasks.stream.audio_input import AudioSource
from skeleton_mamba.tasks.stream.features import FPS, HOP, SR
from skeleton_mamba.tasks.stream.live import LiveDancer
from skeleton_mamba.tasks.stream.model import tokens_to_motion
from skeleton_mamba.tasks.stream.module import StreamDanceModule
from skeleton_mamba.tasks.stream.stream_args import build_parser
from skeleton_mamba.tasks.training.frame_timing import (
    announce_compile,
    latency_summary,
    prepare_live,
    realtime_hint,
    report_compile,
)
from skeleton_mamba.tasks.training.pretrained import load_module_from

__all__ = ["build_parser", "main", "realtime_hint"]


def _load_dancer(ckpt: str):
    return load_module_from(StreamDanceModule, ckpt).model.eval()


def quantize_linear_int8(model: nn.Module) -> nn.Module:
    """``model`` with every ``nn.Linear`` replaced by PyTorch's dynamically quantized int8 Linear
    (``torch.ao.quantization.quantize_dynamic``, int8 weights per output channel; each (..., in) input
    quantized per call, the (..., out) output float32). The frame path calls such a layer itself
    (:func:`~skeleton_mamba.runtime.frame_ops.linear`)."""
    with warnings.catch_warnings():  # torch.ao's quantized modules are deprecated in favour of torchao
        warnings.simplefilter("ignore")
        spec = {nn.Linear: torch.ao.quantization.per_channel_dynamic_qconfig}
        return torch.ao.quantization.quantize_dynamic(model, spec, dtype=torch.qint8)


def stream_dance(args: argparse.Namespace) -> int:

    if not args.music:
        raise InputError("--music FILE (or -) is required for --task dance")
    if args.compile and args.precision != "fp32":
        raise InputError(f"--compile steps in fp32 only: drop --compile or --precision {args.precision}")
    if args.quantize != "none" and (args.compile or args.precision != "fp32"):
        raise InputError(
            f"--quantize {args.quantize} steps eager and in fp32: drop --compile and --precision"
        )
    name = args.name or ("stdin" if args.music == "-" else Path(args.music).stem)
    on_rig = rig_file_names([name], args.rig)
    produced = [*dance_files(name, not args.no_render), f"{name}_stream.json", *on_rig]
    out = claim_output_folder(args.out, "sm stream", produced, overwrite=args.overwrite)
    # the character read and mapped before the music is opened and the checkpoint loaded
    rig = prepare_rig(args, [out / n for n in on_rig], SMPL24.joint_names)
    source = AudioSource(args.music, args.chunk_ms / 1e3, args.realtime, args.raw_rate)
    model = _load_dancer(args.ckpt)
    if args.quantize == "int8":
        model = quantize_linear_int8(model)
    with inference_precision(args.precision):  # the warm-up frame too
        dancer = LiveDancer(model, source.sample_rate, compile=announce_compile(args.compile))
    report_compile(dancer.compile_seconds, args.compile)
    with writing_outputs(out, "sm stream", produced):
        return _dance_into(args, out, name, source, dancer, rig)


def _dance_into(
    args: argparse.Namespace, out: Path, name: str, source: AudioSource, dancer: LiveDancer,
    rig: RigOutput | None = None,
) -> int:  # fmt: skip
    """Stream ``source`` through ``dancer``; write the dance, its video and report as ``name`` in ``out``
    (``rig``: the dance on that character too)."""
    # The music as received, for the video (a live input has no file of its own).
    recording = None if args.music != "-" else Path(tempfile.mkstemp(suffix=".wav", dir=out)[1])
    writer = None if recording is None else sf.SoundFile(recording, "w", source.sample_rate, 1, "PCM_16")
    interrupted = False
    print(
        f"sm stream: dancing to {args.music} ({source.sample_rate} Hz, chunks of {args.chunk_ms:g} ms"
        f"{', real time' if args.realtime else ''}); Ctrl-C ends the stream",
        file=sys.stderr,
    )
    try:
        with inference_precision(args.precision):
            for chunk in source:
                if writer is not None:
                    writer.write(np.clip(chunk.samples, -1.0, 1.0))  # float input may exceed full scale
                dancer.push(chunk.samples, chunk.arrival)
            dancer.push(np.zeros(0, np.float32), last=True)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if writer is not None:
            writer.close()
    try:
        if dancer.num_frames == 0:
            message = f"{args.music}: the music ended before one frame (33 ms) was complete; nothing written"
            if not interrupted:
                raise InputError(message)
            print(f"sm stream: {message}", file=sys.stderr)
            return 130
        width, height = args.render_size
        files = write_motion(
            tokens_to_motion(dancer.tokens().float(), FPS),
            out,
            name,
            music=recording or args.music,
            render=not args.no_render,
            style=RenderStyle(width=width, height=height),
            title=f"live {Path(args.ckpt).name}",
        )
        if rig is not None:  # the dance written above, on the character: same frames and frame rate
            files.rig = rig.write_file(files.npz, out / rig.file_name(name), name)
    finally:  # the received music is only needed for the video; none stays behind in the out folder
        if recording is not None:
            recording.unlink(missing_ok=True)
    latency = latency_summary(dancer.latency_ms)
    report = {
        "frames": dancer.num_frames,
        "fps": FPS,
        "seconds": dancer.num_frames / FPS,
        "realtime": args.realtime,
        "chunk_ms": args.chunk_ms,
        "frame_audio_ms": 1e3 * HOP / SR,
        "resampler_delay_ms": 1e3 * dancer.features.resampler_delay_s,
        "audio_to_pose_latency": latency,
        "compiled": dancer.compile_seconds is not None,
        "compile_seconds": dancer.compile_seconds,
        "precision": args.precision,
        "quantize": args.quantize,
        "interrupted": interrupted,
        "files": {k: str(v) for k, v in vars(files).items() if v is not None},
    }
    with atomic_open(out / f"{name}_stream.json", "w", encoding="utf-8") as f:
        f.write(json.dumps(report, indent=2))
    print(f"sm stream: {dancer.num_frames} poses ({report['seconds']:.1f} s at {FPS} fps) written to {out}")
    print("\n".join(files.lines()))
    print(
        f"  audio-to-pose latency: median {latency['median_ms']:.1f} ms, p99 {latency['p99_ms']:.1f} ms, "
        f"max {latency['max_ms']:.1f} ms (after the frame's own {report['frame_audio_ms']:.1f} ms of audio, "
        f"chunks of {args.chunk_ms:g} ms, resampler delay {report['resampler_delay_ms']:.1f} ms)"
    )
    if (hint := realtime_hint(latency, report["compiled"], FPS)) is not None:
        print(hint, file=sys.stderr)
    return 130 if interrupted else 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.task == "recognition":  # sm routes it to skeleton_mamba.tasks.recognition.online
        raise InputError("--task recognition runs through sm (sm stream --task recognition ...)")
    prepare_live(args.ckpt, args.threads)
    try:
        return stream_dance(args)
    except ValueError as err:  # the audio readers' checks name the file: one line, exit 2
        raise InputError(one_line_message(err)) from err
