"""The demo's long song: one held-out dance of a minute, danced long-form and scored as one dance.

:func:`long_sample` generates a held-out dance of ``duration_s`` seconds (the style, tempo and seed of a
held-out demo dance, so the model never saw it), its music, and builds it as one EgoAIST++-style sample with
the set's builder settings (a procedural room, the egocentric video). :func:`score_long_dance` dances it
as ``sm dance --sample`` does (long-form windows, head targets estimated from the video, the heading read
from it: :mod:`.video_rotation`) and scores it
(:mod:`.long_form_scores`): MPJPE over every window-long span where a window starts (each in its own first
frame) beside the mean-pose baseline and beside the same windows sampled alone (drawn with the same noise,
nothing in-painted: what joining them changes, without the noise of another draw), the dance's dynamics
against the truth's, the seams, and the drift over the song.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from skeleton_mamba.tasks.egodance.builder.build import BuildConfig, run_build
from skeleton_mamba.tasks.egodance.builder.layout import complete_samples
from skeleton_mamba.tasks.egodance.dance_inputs import DanceInputs, sample_inputs
from skeleton_mamba.tasks.egodance.long_form import LongForm, head_targets
from skeleton_mamba.tasks.egodance.long_form_scores import (
    drift,
    long_form_checks,
    seam_frames,
    seam_ratios,
    segments,
)
from skeleton_mamba.tasks.egodance.representation import motion_joints
from skeleton_mamba.tasks.motion.metrics.dynamics import dynamics_ratios
from skeleton_mamba.tasks.motion.metrics.pose_distance import mpjpe
from skeleton_mamba.tasks.motion.synthetic.dance import write_dance as write_synthetic_dance
from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music
from skeleton_mamba.tasks.motion.synthetic.splits import parse_demo_name

__all__ = ["format_long_scores", "long_sample", "score_long_dance"]


def long_sample(data, source: str, duration_s: float) -> Path:
    """The sample folder of a ``duration_s`` version of the generated dance ``source`` (its style, tempo
    and seed), built under the data's root next to its set, with the set's builder settings (reused when
    already built).

    Args:
        data (SyntheticEgoDanceDataModule): the data module the model was trained on
            (:class:`~.data.SyntheticEgoDanceDataModule`).
        source: a held-out generated dance (``synthetic_<style>_<bpm>bpm_s<seed>``).
    """
    hp = data.hparams
    style, bpm, seed = parse_demo_name(source)
    root = data.source_root / f"long_{duration_s:g}s"
    motions = root / "motions"
    motion = write_synthetic_dance(motions, bpm, duration_s, style, seed, float(hp.fps), hp.swing_side)
    write_music(motion.with_suffix(".wav"), synthesize_music(bpm, duration_s, seed=seed))
    config = BuildConfig(out=str(root / "ego"), num_rooms=hp.num_rooms, fps=float(hp.fps),
                         window_s=duration_s, width=hp.frame_size, height=hp.frame_size, seed=hp.seed,
                         workers=1)  # fmt: skip
    run_build(config, motions)
    folders = complete_samples(root / "ego")
    if not folders:
        raise RuntimeError(f"{root / 'ego'}: the long sample could not be placed in a room")
    return folders[0]


def _segment_starts(total: int, long_form: LongForm) -> list[int]:
    """Every window-long segment that fits, starting where a long-form window starts (one every hop: with
    EDGE's half-window overlap each frame lies in two), so the joined dance and its windows sampled alone are
    scored over the same windows, wherever they start in the music."""
    return [s for s in long_form.starts(total) if s + long_form.window <= total]


def _mean_mpjpe(dance: torch.Tensor, truth: torch.Tensor) -> float:
    """Mean MPJPE (m) of segments of tokens (S, W, 24, 10) against their truth."""
    errors = [mpjpe(motion_joints(a).double(), motion_joints(b).double()) for a, b in zip(dance, truth)]
    return float(torch.stack(errors).mean())


def _mean_dynamics(dance: torch.Tensor, truth: torch.Tensor, fps: float) -> dict[str, float]:
    """:func:`dynamics_ratios` of segments (S, W, 24, 10) against their truth, mean over the segments (each
    in its own first frame, so that the slow turn of the whole dance is not read as amplitude)."""
    rows = [
        dynamics_ratios(motion_joints(a).double(), motion_joints(b).double(), fps)
        for a, b in zip(dance, truth)
    ]
    return {k: sum(r[k] for r in rows) / len(rows) for k in rows[0]}


def _head_source(module) -> str:
    """``estimate`` (the head from the video) for a module with a head estimator and a vision encoder."""
    vision = module.ema.module.vision_encoder is not None
    return "estimate" if module.head_estimator is not None and vision else "none"


def _long_windows(
    module, inputs: DanceInputs, long_form: LongForm, join: bool = True, inpaint: bool | None = None
) -> torch.Tensor:
    """The song danced as ``sm dance --sample`` does (the module's EMA model, the head estimated from the
    video, the heading read from it), seeded with the module's evaluation seed: tokens (T, 24, 10), or with
    ``join=False`` the same windows with the same noise sampled each alone, (B, W, 24, 10) in their own
    frames. ``inpaint``: in-paint the overlaps (None: as the module's ``inpaint_overlaps``)."""
    model = module.ema.module
    total = len(inputs.music)
    source = _head_source(module)
    video = None if inputs.video is None else inputs.video.head
    head, head_windows = head_targets(source, long_form, total, module.head_estimator, video)
    return inputs.dance(
        model,
        module.diffusion,
        long_form,
        head=head,
        head_windows=head_windows,
        join=join,
        inpaint=module.inpaint_overlaps if inpaint is None else inpaint,
        **dataclasses.asdict(module.sampling),
        head_guidance_weight=module.head_guidance.weight,
        head_guidance_steps=module.head_guidance.steps,
        generator=torch.Generator().manual_seed(module.evaluation.seed),
    )


def _windows_alone(module, inputs: DanceInputs, long_form: LongForm, starts) -> torch.Tensor:
    """(S, W, 24, 10): the long form's windows starting at ``starts`` (multiples of the hop), drawn with the
    same noise as in the joined song but sampled each alone (nothing in-painted), each in its own frame."""
    if any(s % long_form.hop for s in starts):
        raise ValueError(f"segments start where windows start, every {long_form.hop} frames: {starts}")
    windows = _long_windows(module, inputs, long_form, join=False)
    return windows[[s // long_form.hop for s in starts]]


@torch.no_grad()
def score_long_dance(
    module, folder: Path, mean_pose: torch.Tensor, overlap: int = 75, inpaint: bool | None = None
) -> tuple[torch.Tensor, DanceInputs, dict]:
    """Dance the sample ``folder`` long-form with the module's EMA model and score it (module docstring).

    Args:
        module (EgoDanceModule): a trained :class:`~.module.EgoDanceModule` (eval mode).
        mean_pose: (24, 3) the training poses' mean joint positions (the baseline held still).
        overlap: frames shared by consecutive windows.
        inpaint: in-paint the overlaps (None: as the module's ``inpaint_overlaps``).

    Returns:
        The dance tokens (T, 24, 10), its inputs (music, truth), and the scores with their ``checks``.
    """
    hp = module.hparams
    long_form = LongForm(hp.window, overlap, bool(hp.canonicalize_init_head))
    model = module.ema.module
    source = _head_source(module)
    inputs = sample_inputs(str(folder), module, model, long_form, estimate=source == "estimate")
    total = len(inputs.music)
    tokens = _long_windows(module, inputs, long_form, inpaint=inpaint)
    headings = None if inputs.video is None else inputs.video.heading
    dance, truth = motion_joints(tokens).double(), motion_joints(inputs.truth).double()
    starts = _segment_starts(total, long_form)
    truth_segments = segments(inputs.truth, starts, long_form.window, long_form.canonical)
    long_segments = segments(tokens, starts, long_form.window, long_form.canonical)
    alone = _windows_alone(module, inputs, long_form, starts)
    true_joints = motion_joints(truth_segments).double()
    seams = seam_frames(long_form.starts(total), overlap, total)
    scores = {
        "sample": str(folder),
        "seconds": total / hp.fps,
        "windows": len(long_form.starts(total)),
        "segments": len(starts),
        "head_source": source,
        "heading_source": "video" if headings is not None else "sampled motion",
        "mpjpe_m": _mean_mpjpe(
            segments(tokens, starts, long_form.window, long_form.canonical), truth_segments
        ),
        "windows_alone_mpjpe_m": _mean_mpjpe(alone, truth_segments),
        "mean_pose_mpjpe_m": float(mpjpe(mean_pose.double().expand_as(true_joints), true_joints)),
        "dynamics": _mean_dynamics(long_segments, truth_segments, hp.fps),
        "windows_alone_dynamics": _mean_dynamics(alone, truth_segments, hp.fps),
        "seams": seam_ratios(dance, seams, hp.fps),
        "truth_seams": seam_ratios(truth, seams, hp.fps),
        "drift": drift(tokens, inputs.truth, long_form.window),
    }
    scores["checks"] = long_form_checks(scores)
    return tokens, inputs, scores


def format_long_scores(scores: dict) -> str:
    """The printed lines of :func:`score_long_dance`'s scores."""
    lines = [
        f"  whole-sequence MPJPE (m, {scores['segments']} segments each in its first frame): "
        f"{scores['mpjpe_m']:.3f}   the segments sampled alone: {scores['windows_alone_mpjpe_m']:.3f}   "
        f"mean pose: {scores['mean_pose_mpjpe_m']:.3f}",
        f"  where the dance ends up (heading held by the {scores.get('heading_source', 'sampled motion')}): "
        + "   ".join(f"{k} {v:.3f}" for k, v in scores["drift"].items()),
        "  dynamics / ground truth's (the segments sampled alone): "
        + "   ".join(
            f"{k} {v:.3f} ({scores['windows_alone_dynamics'][k]:.3f})" for k, v in scores["dynamics"].items()
        ),
        "  seams (dance / ground truth's): "
        + "   ".join(f"{k} {v:.3f} / {scores['truth_seams'][k]:.3f}" for k, v in scores["seams"].items()),
    ]
    lines += [f"{'reached' if ok else 'NOT reached'}: {check}" for check, ok in scores["checks"].items()]
    return "\n".join(lines)
