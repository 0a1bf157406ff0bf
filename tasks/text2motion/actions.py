"""Everyday actions for the text-to-motion demo: the captions it trains on, the paraphrases it is asked with,
and a reader that tells from a motion's joints which action it shows.

Training captions (:data:`CAPTIONS`, several per action) and the demo's prompts (:data:`PARAPHRASES`) use
different words for the action itself (``walks`` / ``strolls``, ``jumps`` / ``hops``): a prompt shows its
action only if the text encoder carries the meaning, not the words, to the motion.

:func:`read_action` is an independent rule on the joints (HumanML3D-22 / SMPL order, metres, y-up), measured
against the motion itself: its floor (the lowest foot), its standing pelvis height (the clip's upper
decile), the pelvis' path and the body's heading (from the hips' left-right axis), each wrist against the
head, each ankle against the floor. In that order it reads:

- ``jump``: both ankles 0.12 m or more above their lowest at once, the pelvis 0.12 m above its median;
- ``squat``: the pelvis 0.28 m or more below standing;
- ``walk``: the pelvis travels 1.5 m or more;
- ``turn``: the heading turns 60 degrees or more while the pelvis travels less than 0.8 m;
- ``wave``: a wrist above the head in a quarter of the frames or more;
- ``run_in_place``: each knee, in turn, within 0.2 m of its hip's height in 10 % of the frames or more;
- ``kick``: an ankle 0.35 m or more above the floor (one leg: both knees high is running in place);

and ``None`` when none of these holds (standing, swaying).
"""

from __future__ import annotations

import numpy as np

__all__ = ["ACTION_WORDS", "CAPTIONS", "PARAPHRASES", "read_action"]

CAPTIONS: dict[str, tuple[str, ...]] = {
    "walk": (
        "a person walks forward.",
        "someone walks along a path.",
        "a man walks ahead at a steady pace.",
        "a woman is walking forward slowly.",
    ),
    "turn": (
        "a person turns around.",
        "someone turns to the side in place.",
        "a man turns his body around while standing.",
        "a woman is turning around on the spot.",
    ),
    "jump": (
        "a person jumps up twice.",
        "someone jumps in place.",
        "a man jumps up and lands.",
        "a woman is jumping up and down.",
    ),
    "squat": (
        "a person squats down and stands back up.",
        "someone squats down low.",
        "a man does a squat.",
        "a woman is squatting down then rising.",
    ),
    "kick": (
        "a person kicks with one leg.",
        "someone kicks forward.",
        "a man kicks a leg out in front.",
        "a woman is kicking with her foot.",
    ),
    "wave": (
        "a person waves a hand above the head.",
        "someone waves hello.",
        "a man raises his hand and waves.",
        "a woman is waving her arm overhead.",
    ),
    "run_in_place": (
        "a person runs in place.",
        "someone runs on the spot.",
        "a man runs in place lifting his knees.",
        "a woman is running in place quickly.",
    ),
}

PARAPHRASES: dict[str, tuple[str, ...]] = {
    "walk": ("someone strolls ahead.", "the person takes a stroll forward."),
    "turn": ("someone spins around.", "the person rotates to face the other way."),
    "jump": ("someone hops up and down.", "the person leaps into the air."),
    "squat": ("someone crouches down.", "the person bends the knees and crouches low."),
    "kick": ("someone punts an imaginary ball.", "the person boots something with the foot."),
    "wave": ("someone greets with a raised hand.", "the person says hi with the hand up high."),
    "run_in_place": ("someone jogs on the spot.", "the person jogs without moving forward."),
}

ACTION_WORDS: dict[str, tuple[str, ...]] = {  # the words a training caption names its action with
    "walk": ("walk", "walks", "walking"),
    "turn": ("turn", "turns", "turning"),
    "jump": ("jump", "jumps", "jumping"),
    "squat": ("squat", "squats", "squatting"),
    "kick": ("kick", "kicks", "kicking"),
    "wave": ("wave", "waves", "waving"),
    "run_in_place": ("run", "runs", "running"),
}

_PELVIS, _L_HIP, _R_HIP, _L_KNEE, _R_KNEE, _L_ANKLE, _R_ANKLE, _HEAD, _L_WRIST, _R_WRIST = (
    0, 1, 2, 4, 5, 7, 8, 15, 20, 21,
)  # fmt: skip
_FEET = (7, 8, 10, 11)


def read_action(joints: np.ndarray) -> str | None:
    """The action ``joints`` (T, 22+, 3), metres, y-up, show (module docstring), or None."""
    joints = np.asarray(joints, np.float64)
    floor = joints[:, _FEET, 1].min()
    y = joints[..., 1] - floor
    pelvis = y[:, _PELVIS]
    standing = np.quantile(pelvis, 0.9)
    ankles = y[:, [_L_ANKLE, _R_ANKLE]]
    airborne = ((ankles - ankles.min(0)).min(1) > 0.12) & (pelvis > np.median(pelvis) + 0.12)
    if airborne.any():
        return "jump"
    if pelvis.min() < standing - 0.28:
        return "squat"
    path = joints[:, _PELVIS][:, [0, 2]]
    travel = float(np.linalg.norm(path[-1] - path[0]))
    if travel >= 1.5:
        return "walk"
    across = joints[:, _L_HIP][:, [0, 2]] - joints[:, _R_HIP][:, [0, 2]]
    heading = np.unwrap(np.arctan2(across[:, 0], across[:, 1]))
    if abs(np.degrees(heading[-1] - heading[0])) >= 60 and travel < 0.8:
        return "turn"
    above = (y[:, [_L_WRIST, _R_WRIST]] > y[:, [_HEAD]]).any(1)
    if above.mean() >= 0.25:
        return "wave"
    pairs = ((_L_KNEE, _L_HIP), (_R_KNEE, _R_HIP))
    knees_high = [np.mean(y[:, knee] > y[:, hip] - 0.2) for knee, hip in pairs]
    if min(knees_high) >= 0.1:
        return "run_in_place"
    if y[:, [_L_ANKLE, _R_ANKLE]].max() >= 0.35:
        return "kick"
    return None
