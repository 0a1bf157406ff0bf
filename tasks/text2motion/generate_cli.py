"""``sm generate --checkpoint CKPT --text "a person walks" --length 6s --out DIR``.

Samples motions from a trained :class:`~.module.TextToMotionModule` checkpoint. For each caption and
repetition it writes, in ``DIR``:

- ``NNN_<words>.npy``: joint positions (T, 22, 3), metres, y-up, 20 fps (``sm render`` reads it);
- ``NNN_<words>_features.npy``: the de-normalised HumanML3D features (T, 263);
- ``NNN_<words>.gif`` / ``.mp4`` with ``--render gif|mp4``;
- ``NNN_<words>_rig.glb`` / ``.vrm`` / ``.bvh`` with ``--rig RIG`` (``--map``): the motion on that character
  (:mod:`~skeleton_mamba.tasks.motion.retarget.rig_output`).

``--length`` is seconds with an ``s`` suffix (``6s`` = 120 frames) or a frame count (``120``).
Sampling takes the checkpoint's settings unless ``--sampler ddim|ddpm|dpmpp|unipc``, ``--steps`` (alone on a
DDPM checkpoint it selects DDIM), ``--eta`` or ``--guidance`` (the classifier-free guidance scale) say
otherwise, as for ``sm dance``; ``dpmpp`` / ``unipc`` are the few-step solvers [DPM-Solver++] and [UniPC].
"""

from __future__ import annotations

import contextlib
import re
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.errors import CheckpointError, InputError
from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.skeletons import HUMANML3D22
from skeleton_mamba.tasks.motion.formats.gltf import from_joints, write_glb
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FPS, recover_from_ric
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_folder, writing_outputs
from skeleton_mamba.tasks.motion.io.value_checks import non_finite_message
from skeleton_mamba.tasks.motion.render.skeleton import render_motion
from skeleton_mamba.tasks.motion.retarget.rig_output import prepare_rig, rig_file_names
from skeleton_mamba.tasks.text2motion.generate_args import build_parser
from skeleton_mamba.tasks.text2motion.module import TextToMotionModule
from skeleton_mamba.tasks.training.pretrained import check_model_source, load_module_from
from skeleton_mamba.tasks.training.sampling_args import checked_sampling, sampling_overrides

__all__ = ["MAX_FRAMES_PER_RUN", "parse_length", "slug", "save_generated", "main"]

MAX_FRAMES_PER_RUN = 6000
"""Frames one ``sm generate`` run makes in all (captions x samples x length): 5 min at 20 fps. Sampling
holds every frame's activations (the demo model: about 190 KB per frame on top of 0.7 GB, measured on a
2-core CPU), so an unbounded ``--length`` exhausts memory before it writes anything."""


def parse_length(text: str) -> int:
    """``"6s"`` / ``"2.5s"`` -> frames at 20 fps (rounded); ``"120"`` -> 120 frames."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?)\s*(s?)\s*", text)
    if match is None:
        raise ValueError(f"length must be seconds like '6s' or a frame count like '120', got {text!r}")
    value, seconds = float(match.group(1)), match.group(2) == "s"
    frames = int(round(value * FPS)) if seconds else int(value)
    if frames < 4 or (not seconds and value != int(value)):
        raise ValueError(f"length {text!r} gives {frames} frames; need a whole number of at least 4 frames")
    return frames


def slug(caption: str) -> str:
    """Up to six lower-case words of a caption joined by ``_`` (file names)."""
    return "_".join(re.findall(r"[a-z0-9]+", caption.lower())[:6]) or "motion"


def save_generated(
    features: torch.Tensor, caption: str, stem: str | Path, render: str | None = None
) -> dict[str, Path]:
    """Write one generated motion: ``STEM.npy`` joints (T, 22, 3), ``STEM_features.npy`` (T, 263), and
    ``STEM.gif`` / ``STEM.mp4`` when ``render`` is ``"gif"`` / ``"mp4"``.

    Args:
        features: de-normalised features (T, 263) (only the valid frames).
        caption: the prompt (the video title).
        stem: output path without suffix; its folder is created.
        render: ``None``, ``"gif"`` or ``"mp4"``.

    Returns:
        ``{"joints": ..., "features": ..., "glb": ..., "video": ...}`` paths (``video`` only when rendered).

    Raises:
        InputError: the features or the joints recovered from them hold NaN or Inf (nothing is written).
    """
    stem = Path(stem)
    features = features.detach().cpu()
    joints = recover_from_ric(features.double()).float().numpy()
    for name, array in (("features", features.float().numpy()), ("joints", joints)):
        message = non_finite_message(array, name, ("frame",))
        if message is not None:  # checked before anything is written
            raise InputError(f"{stem}: generated motion is not finite ({message}); nothing written")
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = {"joints": stem.with_suffix(".npy"), "features": stem.with_name(stem.name + "_features.npy")}
    for key, array in (("features", features.float().numpy()), ("joints", joints)):
        with atomic_open(paths[key], "wb") as f:
            np.save(f, array)
    paths["glb"] = write_glb(from_joints(joints, HUMANML3D22.name, FPS), stem.with_suffix(".glb"), stem.name)
    if render:
        paths["video"] = render_motion(
            joints,
            HUMANML3D22.parents,
            stem.with_suffix(f".{render}"),
            FPS,
            names=HUMANML3D22.joint_names,
            title=caption,
            progress=False,
        )
    return paths


@contextlib.contextmanager
def _no_loading_bar() -> Iterator[None]:
    """Hide transformers' weight-loading bar while the text encoder is built (it loads in well under a
    second from a local folder; the bar would stand above a refusal's one line)."""
    from transformers.utils import logging as transformers_logging  # lazy: transformers' import is slow

    shown = transformers_logging.is_progress_bar_enabled()
    transformers_logging.disable_progress_bar()
    try:
        yield
    finally:
        if shown:
            transformers_logging.enable_progress_bar()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm generate``; returns 0 on success (bad input raises: `sm` prints one line)."""
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    # everything cheap is refused before the checkpoint and the text encoder are loaded
    try:
        frames = parse_length(args.length)
    except ValueError as e:
        raise InputError(str(e)) from e  # names the text given
    captions = [c for c in args.text for _ in range(args.num)]
    if frames * len(captions) > MAX_FRAMES_PER_RUN:
        raise InputError(
            f"--length {args.length} x {len(captions)} motion(s) = {frames * len(captions)} frames; "
            f"sm generate makes at most {MAX_FRAMES_PER_RUN} frames per run "
            f"({MAX_FRAMES_PER_RUN / FPS / 60:g} min at {FPS:g} fps; memory grows with every frame): shorten "
            "--length or generate fewer at a time"
        )
    stems = [f"{i:03d}_{slug(caption)}" for i, caption in enumerate(captions)]
    suffixes = (".npy", "_features.npy", ".glb", *((f".{args.render}",) if args.render else ()))
    on_rig = rig_file_names(stems, args.rig)
    produced = [stem + suffix for stem in stems for suffix in suffixes] + on_rig
    out = claim_output_folder(args.out, "sm generate", produced, overwrite=args.overwrite)
    # the character read and mapped before the checkpoint and the text encoder are loaded
    rig = prepare_rig(args, [out / n for n in on_rig], list(HUMANML3D22.joint_names))
    overrides = sampling_overrides(args)
    check_model_source(args.checkpoint)  # the text as given: a URL is refused as one

    with _no_loading_bar():  # a refused checkpoint leaves one line on stderr, not a bar above it
        module = load_module_from(TextToMotionModule, args.checkpoint).eval()
    # the sampling against the loaded model's step count, before any caption is encoded
    used = checked_sampling(args, module.sampling, module.diffusion.num_steps, args.checkpoint)
    features, _ = module.generate(
        captions,
        [frames] * len(captions),
        generator=torch.Generator().manual_seed(args.seed),
        progress=args.progress,
        **overrides,
    )
    for i, caption in enumerate(captions):  # every motion checked before the first is written
        message = non_finite_message(features[i].float().numpy(), "features", ("frame",))
        if message is not None:
            raise CheckpointError(
                f"{args.checkpoint}: the model generated non-finite motion for {caption!r} ({message}); "
                "nothing written"
            )
    described = used.describe()  # what module.generate sampled with
    print("sampled with " + ", ".join(f"{k} {v}" for k, v in described.items()))
    with writing_outputs(args.out, "sm generate", produced) as out:
        for i, caption in enumerate(captions):
            paths = save_generated(features[i], caption, out / stems[i], args.render)
            if rig is not None:  # the joints written above, on the character: same frames and frame rate
                rig_out = out / rig.file_name(stems[i])
                paths["rig"] = rig.write_file(paths["joints"], rig_out, stems[i], HUMANML3D22.name, FPS)
            print(f"{caption!r}: {frames} frames at {FPS:g} fps")
            print("\n".join(f"  {kind:8s} {path}" for kind, path in paths.items()))
    return 0
