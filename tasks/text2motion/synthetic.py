"""A SYNTHETIC captioned motion set for demos without HumanML3D (no download).

Each clip is, by default (:data:`KINDS`), a procedural dance of
:mod:`skeleton_mamba.tasks.motion.synthetic.dance` (``bounce``, ``sway``, ``arms``; random tempo 90-140 BPM)
with a caption of its style (:data:`DANCE_CAPTIONS`), or, when asked for, one of the everyday actions people
type (:mod:`skeleton_mamba.tasks.motion.synthetic.actions`: walk, turn, jump, squat, kick, wave, run in place;
drawn with the clip's seed) with a caption of its action (:data:`CAPTIONS`: four wordings each; the demo
prompts with paraphrases none of them uses). Clips have a random length at 20 fps and are turned into the
HumanML3D 263-d representation by
:func:`~skeleton_mamba.tasks.motion.formats.humanml3d_features.joints_to_features` (the SMPL-24 joints 0..21
as the 22 HumanML3D joints, the SMPL local rotations as the 6D rotations). Every caption starts with
"synthetic:" so generated demo data is never mistaken for HumanML3D.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix, matrix_to_rotation_6d
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FPS, NUM_JOINTS, joints_to_features
from skeleton_mamba.tasks.motion.synthetic.actions import ACTIONS, synthesize_action
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance
from skeleton_mamba.tasks.text2motion.actions import CAPTIONS as ACTION_CAPTIONS
from skeleton_mamba.tasks.text2motion.humanml3d import Caption, MotionClip

__all__ = ["CAPTIONS", "DANCE_CAPTIONS", "KINDS", "LABEL", "check_kinds", "synthetic_clip", "synthetic_clips"]

LABEL = "synthetic: "  # every synthetic caption and demo prompt starts with it
DANCE_CAPTIONS: dict[str, tuple[str, ...]] = {
    "bounce": (
        "synthetic: a person bounces to the beat, bending the knees.",
        "synthetic: someone bobs up and down in place while swinging the arms.",
    ),
    "sway": (
        "synthetic: a person sways the hips from side to side.",
        "synthetic: someone rocks the torso left and right with loose arms.",
    ),
    "arms": (
        "synthetic: a person waves both arms up and down.",
        "synthetic: someone raises and lowers the arms in big waves.",
    ),
}
CAPTIONS: dict[str, tuple[str, ...]] = {
    action: tuple(LABEL + text for text in texts) for action, texts in ACTION_CAPTIONS.items()
}
KINDS = tuple(sorted(DANCE_CAPTIONS))  # the demo's clips: the dances (ACTIONS: the everyday actions)


def synthetic_clip(style: str, frames: int, seed: int) -> MotionClip:
    """One captioned clip of ``frames`` feature frames (``frames + 1`` positions) at 20 fps: an action of
    :data:`CAPTIONS` or a dance style of :data:`DANCE_CAPTIONS`."""
    rng = np.random.default_rng(seed)
    if style in ACTIONS:
        motion = synthesize_action(style, (frames + 1) / FPS, fps=FPS, seed=seed)
        captions = CAPTIONS[style]
    else:
        bpm = float(rng.integers(90, 141))
        motion = synthesize_dance(bpm, (frames + 1) / FPS, fps=FPS, style=style, seed=seed)
        captions = DANCE_CAPTIONS[style]
    joints = torch.from_numpy(motion.joint_positions()[: frames + 1, :NUM_JOINTS]).double()
    local = axis_angle_to_matrix(torch.from_numpy(motion.poses[: frames + 1, 1:NUM_JOINTS]).double())
    features = joints_to_features(joints, matrix_to_rotation_6d(local)).float().numpy()
    text = captions[int(rng.integers(len(captions)))]
    caption = Caption(text, tuple(f"{w.strip('.,:')}/OTHER" for w in text.split()), 0.0, 0.0)
    return MotionClip(f"synthetic_{style}_{seed}", features, [caption])


def check_kinds(kinds: Sequence[str]) -> None:
    """Refuse clip kinds that are neither an action of :data:`CAPTIONS` nor a dance of :data:`DANCE_CAPTIONS`
    (or none at all)."""
    unknown = sorted(set(kinds) - set(CAPTIONS) - set(DANCE_CAPTIONS))
    if unknown or not kinds:
        raise ValueError(f"unknown clip kinds {unknown}; known: {', '.join([*CAPTIONS, *DANCE_CAPTIONS])}")


def synthetic_clips(
    count: int, seed: int = 0, min_frames: int = 40, max_frames: int = 196, kinds: Sequence[str] = KINDS
) -> list[MotionClip]:
    """``count`` clips of ``kinds`` (actions of :data:`CAPTIONS`, dance styles of :data:`DANCE_CAPTIONS`) in
    turn, lengths uniform in ``[min_frames, max_frames]``."""
    check_kinds(kinds)
    rng = np.random.default_rng(seed)
    styles = list(kinds)
    clips = []
    for k in range(count):
        frames = int(rng.integers(min_frames, max_frames + 1))
        clips.append(synthetic_clip(styles[k % len(styles)], frames, seed * 100_003 + k))
    return clips
