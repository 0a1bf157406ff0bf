"""``sm dance``: estimate a dance with a trained EMM checkpoint; writes the motion (.npz, BVH) and an mp4.

Examples::

    sm dance --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt \\
        --sample runs/egodance_demo/data/ego/samples/<id> --out dance/
    sm dance --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt --list-samples
    sm dance --ckpt last.ckpt --music song.wav --video ego.mp4 --out dance/ --sampler ddpm

``--sample`` reads an EgoAIST++ sample folder of any length (music slice, egocentric frames and the
ground-truth camera trajectory) and prints the dance's scores against its ground truth; ``--list-samples``
prints the held-out (test, then val) sample folders of the checkpoint's data, one per line, which the model
never saw in training. ``--head`` chooses the head-guidance targets: ``estimate`` (the default for vision
models: the checkpoint's head-trajectory estimator on the egocentric frames, what any video allows),
``oracle`` (the sample's ground-truth camera path; ``--sample`` only, printed as oracle) or ``none``.
``--music`` (+ ``--video`` for vision models: a video file or a folder of images) dances a whole track: tracks
longer than the training window are sampled as overlapping windows whose overlaps are in-painted at every
denoising step (EDGE long-form), ``--batch-windows`` at a time, so a 60 s song gives one continuous dance in
bounded memory. A video shorter than the music: the dance covers the part where both are (said before the
video is decoded); a video of another frame rate is taken at the model's. ``--out DIR`` receives
``<name>.npz`` (our motion format), ``<name>.bvh`` and ``<name>.mp4`` (the skeleton with the music muxed in;
``--no-render`` skips it); ``--out FILE.npz`` names the files after FILE; ``--rig RIG`` (``--map``) also
writes the dance on that character, ``<name>_rig.glb`` / ``.vrm`` / ``.bvh``. A checkpoint trained with
``canonicalize_init_head`` (the demo's), whose windows face their first frame's head heading, samples each
window in that frame, found from the previous window's dance, with head targets estimated per window; the
windows are turned back and joined (:mod:`.heading_frames`).
"""

from __future__ import annotations

import dataclasses
import time
from contextlib import nullcontext
from pathlib import Path

import torch

from skeleton_mamba.errors import InputError
from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.ssd.precision import inference_precision
from skeleton_mamba.tasks.egodance.dance_args import build_parser
from skeleton_mamba.tasks.egodance.dance_inputs import DanceInputs, sample_inputs, track_inputs
from skeleton_mamba.tasks.egodance.data import data_module_from_hparams
from skeleton_mamba.tasks.egodance.export import write_dance
from skeleton_mamba.tasks.egodance.long_form import LongForm, head_targets
from skeleton_mamba.tasks.egodance.module import EgoDanceModule
from skeleton_mamba.tasks.egodance.representation import motion_joints
from skeleton_mamba.tasks.motion.formats.export import dance_files
from skeleton_mamba.tasks.motion.io.output_folder import (
    claim_output_files,
    claim_output_folder,
    writing_outputs,
)
from skeleton_mamba.tasks.motion.metrics.beat_align import sequence_beat_align
from skeleton_mamba.tasks.motion.metrics.dynamics import DYNAMICS_METRICS, dynamics_ratios
from skeleton_mamba.tasks.motion.metrics.pose_distance import mpjpe
from skeleton_mamba.tasks.motion.music.features import BEAT
from skeleton_mamba.tasks.motion.render.skeleton import RenderStyle
from skeleton_mamba.tasks.motion.retarget.rig_output import prepare_rig, rig_file_names
from skeleton_mamba.tasks.training.diffusion.sampling import SamplingOptions
from skeleton_mamba.tasks.training.pretrained import load_module_and_checkpoint_from
from skeleton_mamba.tasks.training.sampling_args import checked_sampling

__all__ = ["main", "build_parser"]


def _denoiser(args, module) -> torch.nn.Module:
    """The EMM the dance is sampled with: the EMA weights, or the raw ones (``--no-ema``)."""
    return module.model if args.no_ema else module.ema.module


def _head_source(args, module) -> str:
    return args.head or ("estimate" if module.head_estimator is not None else "none")


def _long_form(args, module, checkpoint: dict) -> LongForm:
    """The windows of the dance: the command's window and overlap, and whether the model's windows face
    their first heading (the module's setting; a checkpoint from before it was one: its data module's)."""
    data = checkpoint.get("datamodule_hyper_parameters") or {}
    canonical = module.hparams.get("canonicalize_init_head") or data.get("canonicalize_init_head", False)
    return LongForm(args.window, args.overlap, bool(canonical))


def _inputs(args, module, long_form: LongForm) -> DanceInputs:
    estimate = _head_source(args, module) == "estimate" and module.head_estimator is not None
    model = _denoiser(args, module)
    with inference_precision(args.precision):  # the encoders in the dance's precision, as in the sampler
        heading = args.heading == "video"
        if args.sample:
            return sample_inputs(args.sample, module, model, long_form, estimate, args.progress, heading)
        fov = args.fov if heading else None
        return track_inputs(args.music, args.video, module, model, long_form, estimate, args.progress, fov)


def _dance(
    args, module, inputs: DanceInputs, long_form: LongForm, sampling: SamplingOptions
) -> tuple[torch.Tensor, str]:
    """The dance tokens (T, 24, C) in fp32 and the head source, in the caller's precision region."""
    source = _head_source(args, module)
    video = None if inputs.video is None else inputs.video.head
    estimator = module.head_estimator
    head, head_windows = head_targets(
        source, long_form, len(inputs.music), estimator, video, inputs.truth, inputs.head
    )
    tokens = inputs.dance(
        _denoiser(args, module),
        module.diffusion,
        long_form,
        head=head,
        head_windows=head_windows,
        batch_windows=args.batch_windows,
        inpaint=module.inpaint_overlaps if args.inpaint is None else args.inpaint == "yes",
        **dataclasses.asdict(sampling),
        head_guidance_weight=module.head_guidance.weight if args.head_weight is None else args.head_weight,
        head_guidance_steps=module.head_guidance.steps,
        generator=torch.Generator().manual_seed(args.seed),
        progress=args.progress,
        compile=args.compile,
    )
    return tokens.float(), source


def _score_against_truth(tokens: torch.Tensor, inputs: DanceInputs, fps: float) -> list[str]:
    """Lines scoring a --sample's dance against its ground truth (joints from FK, metres)."""
    dance, truth = motion_joints(tokens), motion_joints(inputs.truth.float())
    beats = inputs.music[:, BEAT]
    ratios = dynamics_ratios(dance, truth, fps)
    scores = {
        "MPJPE to the ground truth (m)": float(mpjpe(dance.double(), truth.double())),
        "BeatAlign with the music (the ground truth's)": (
            f"{sequence_beat_align(dance, beats, 'bailando', fps):.3f} "
            f"({sequence_beat_align(truth, beats, 'bailando', fps):.3f})"
        ),
        **{DYNAMICS_METRICS[k]: v for k, v in ratios.items()},
    }
    return [f"sm dance: {name}: {v:.3f}" if isinstance(v, float) else f"sm dance: {name}: {v}"
            for name, v in scores.items()]  # fmt: skip


def held_out_samples(data_hparams: dict) -> dict[str, list[Path]]:
    """``test`` and ``val`` sample folders of the data a checkpoint was trained on, from its data module's
    hyper-parameters (the generated demo set when they have a ``count``, else an EgoAIST++ build)."""
    data = data_module_from_hparams(data_hparams)
    try:
        splits = data.split_folders()
    except FileNotFoundError as err:  # DatasetNotFoundError says what is missing and how to build it
        raise InputError(f"the checkpoint's data: {err}") from err
    return {split: splits[split] for split in ("test", "val") if splits[split]}


def _list_samples(ckpt: str, checkpoint: dict) -> int:
    data_hparams = checkpoint.get("datamodule_hyper_parameters") or {}
    if not data_hparams:
        raise InputError(f"{ckpt}: holds no data module hyper-parameters; its held-out samples are unknown")
    found = held_out_samples(data_hparams)
    if not found:
        raise InputError(f"{ckpt}: its data holds no held-out (test / val) sample")
    for split, folders in found.items():
        print(
            f"# {split}: {len(folders)} held-out samples (sm dance --ckpt {ckpt} --sample FOLDER --out DIR)"
        )
        print("\n".join(str(folder) for folder in folders))
    return 0


def _output_names(out: str, name: str, render: bool, rig: str | None) -> tuple[Path, str, list[str]]:
    """The folder, the stem and the file names of the dance (``rig``: the ``--rig`` file, its one too)."""
    path = Path(out)
    folder, stem = (path.parent, path.stem) if path.suffix.lower() == ".npz" else (path, name)
    return folder, stem, dance_files(stem, render) + rig_file_names([stem], rig)


def claim_dance_output(out: str, name: str, render: bool, overwrite: bool, rig: str | None = None) -> None:
    """``--out DIR``: a folder this command may write into; ``--out FILE.npz``: no file beside it replaced
    (:mod:`~skeleton_mamba.tasks.motion.io.output_folder`)."""
    path = Path(out)
    folder, _, names = _output_names(out, name, render, rig)
    if path.suffix.lower() == ".npz":
        claim_output_files([folder / n for n in names], path, overwrite=overwrite)
    else:
        claim_output_folder(path, "sm dance", names, overwrite=overwrite)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.list_samples and not args.out:
        parser.error("the following arguments are required: --out")
    if not args.no_render and (args.render_size[0] % 16 or args.render_size[1] % 16):
        raise InputError(f"--render-size {args.render_size[0]}x{args.render_size[1]}: use multiples of 16")
    if args.head == "oracle" and not args.sample:
        raise InputError("--head oracle needs the ground-truth camera path of a --sample")
    rig = None
    if not args.list_samples:  # the arguments first, then the output, then any work
        claim_dance_output(args.out, args.name, not args.no_render, args.overwrite, args.rig)
        folder, stem, _ = _output_names(args.out, args.name, not args.no_render, args.rig)
        # the character read and mapped before the checkpoint, the music and the video
        rig = prepare_rig(args, [folder / n for n in rig_file_names([stem], args.rig)], SMPL24.joint_names)

    # checked: local, weights_only, project classes; read once
    module, checkpoint = load_module_and_checkpoint_from(EgoDanceModule, args.ckpt)
    if args.list_samples:
        return _list_samples(args.ckpt, checkpoint)
    module.eval()
    # the settings against the loaded model, before any input is read
    sampling = checked_sampling(args, module.sampling, module.diffusion.num_steps, args.ckpt)
    fps = module.hparams.fps  # the frame rate the model was trained at (linked from its data module)
    long_form = _long_form(args, module, checkpoint)
    if args.compile and args.precision != "fp32":
        raise InputError(
            f"--compile runs the denoiser in fp32 only: drop --compile or --precision {args.precision}"
        )
    turns = _denoiser(args, module).heading_embedding is not None  # the EMM reads the head's turns
    if turns and args.heading == "none":
        raise InputError("this model dances to the head's turns read from the video: drop --heading none")
    try:
        inputs = _inputs(args, module, long_form)
    except ValueError as err:  # the music, video or sample files (their readers name the file)
        raise InputError(str(err)) from err
    if turns and (inputs.video is None or inputs.video.heading is None):
        raise InputError(
            f"{args.video or args.sample}: the head's turns could not be read from this video (frames a "
            "rotation does not explain), and this model dances to them; try --fov with the camera's field of "
            "view"
        )
    seconds = dict(inputs.seconds)
    start = time.perf_counter()
    with inference_precision(args.precision):
        tokens, head_source = _dance(args, module, inputs, long_form, sampling)
    seconds["sampling"] = time.perf_counter() - start
    start = time.perf_counter()
    out = Path(args.out)
    out_dir, name, names = _output_names(args.out, args.name, not args.no_render, args.rig)
    width, height = args.render_size
    into_folder = out.suffix.lower() != ".npz"
    with writing_outputs(out_dir, "sm dance", names) if into_folder else nullcontext():
        files = write_dance(
            tokens,
            out_dir,
            name,
            music=inputs.music_path,
            music_start_s=inputs.music_start_s,
            render=not args.no_render,
            style=RenderStyle(width=width, height=height),
            title=f"EMM {Path(args.ckpt).name}",
            progress=args.progress,
            fps=fps,
        )
        if rig is not None:  # the dance written above, on the character: same frames and frame rate
            files.rig = rig.write_file(files.npz, out_dir / rig.file_name(name), name)
    seconds["writing"] = time.perf_counter() - start
    duration = tokens.shape[0] / fps
    guidance = {
        "estimate": "head guidance from the head trajectory estimated from the video",
        "oracle": "head guidance from the ORACLE (ground-truth) camera path",
        "none": "no head guidance",
    }[head_source]
    print(f"sm dance: {guidance}")
    starts = long_form.starts(tokens.shape[0])
    if len(starts) > 1:
        turned = ""
        if long_form.canonical:
            held = inputs.video is not None and inputs.video.heading is not None
            by = "the head's turns read from the video" if held else "the sampled motion"
            turned = f", each facing its first frame's head heading, held by {by}"
        print(f"sm dance: {len(starts)} windows of {long_form.window} frames every {long_form.hop}{turned}, "
              "joined into one dance")  # fmt: skip
    print(f"sm dance: {tokens.shape[0]} frames ({duration:.1f} s at {fps:g} fps) written to", out_dir)
    print("\n".join(files.lines()))
    if inputs.truth is not None:
        print("\n".join(_score_against_truth(tokens, inputs, fps)))
    print("sm dance: seconds per stage: " + ", ".join(f"{k} {v:.1f}" for k, v in seconds.items()))
    return 0
