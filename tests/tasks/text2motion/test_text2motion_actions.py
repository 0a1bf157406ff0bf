"""The text-to-motion demo's everyday actions: procedural clips of each (through the HumanML3D features and
back) are read as that action by the independent rule, dances and standing as none; the demo's prompts never
use a training caption's word for their action; the rule's thresholds on hand-made motions."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from skeleton_mamba.tasks.motion.formats.humanml3d_features import recover_from_ric
from skeleton_mamba.tasks.motion.synthetic.actions import ACTIONS, synthesize_action
from skeleton_mamba.tasks.text2motion.actions import ACTION_WORDS, CAPTIONS, PARAPHRASES, read_action
from skeleton_mamba.tasks.text2motion.demo_scores import action_checks, action_scores
from skeleton_mamba.tasks.text2motion.synthetic import LABEL, synthetic_clip, synthetic_clips


def _joints(clip) -> np.ndarray:
    return recover_from_ric(torch.from_numpy(clip.features).double()).numpy()


@pytest.mark.parametrize("action", ACTIONS)
def test_every_synthetic_clip_of_an_action_is_read_as_that_action(action):
    for seed in range(8):
        for frames in (40, 120, 196):
            clip = synthetic_clip(action, frames, seed)
            text = clip.captions[0].text
            assert text.startswith(LABEL) and text[len(LABEL) :] in CAPTIONS[action]
            assert read_action(_joints(clip)) == action, (seed, frames)


def test_dances_and_standing_show_no_action():
    for style in ("bounce", "sway", "arms"):
        for seed in range(4):
            assert read_action(_joints(synthetic_clip(style, 120, seed))) is None, (style, seed)
    standing = synthesize_action("walk", 3.0, 20.0, 0).joint_positions()[:1].repeat(60, 0)[:, :22]
    assert read_action(standing) is None


def test_the_prompts_never_use_a_training_captions_word_for_their_action():
    for action, texts in PARAPHRASES.items():
        for text in texts:
            words = {w.strip(".,:") for w in text.lower().split()}
            assert not words & set(ACTION_WORDS[action]), text
            for other in ACTION_WORDS.values():  # nor another action's word
                assert not words & set(other), text
        for caption in CAPTIONS[action]:
            assert {w.strip(".,") for w in caption.split()} & set(ACTION_WORDS[action]), caption
    assert set(PARAPHRASES) == set(CAPTIONS) == set(ACTIONS)


def test_the_rule_on_hand_made_motions():
    base = synthesize_action("turn", 3.0, 20.0, 1).joint_positions()[:1, :22].repeat(60, 0)
    moved = base.copy()
    moved[:, :, 2] += np.linspace(0, 1.6, 60)[:, None]  # carried 1.6 m without a step: travels
    assert read_action(moved) == "walk"
    moved[:, :, 2] = base[:, :, 2] + np.linspace(0, 1.4, 60)[:, None]  # 1.4 m: not yet
    assert read_action(moved) is None
    lowered = base.copy()
    lowered[30:, [0, 1, 2, 3], 1] -= 0.3  # the pelvis 0.3 m below standing
    assert read_action(lowered) == "squat"
    raised = base.copy()
    raised[10:40, 20, 1] = raised[10:40, 15, 1] + 0.1  # a wrist above the head for half the clip
    assert read_action(raised) == "wave"


def test_synthetic_clips_cycle_their_kinds_and_scores_count_hits():
    assert [c.motion_id.split("_")[1] for c in synthetic_clips(3, seed=3)] == ["arms", "bounce", "sway"]
    clips = synthetic_clips(14, seed=3, min_frames=40, max_frames=60, kinds=ACTIONS)
    assert [c.motion_id.split("_")[1] for c in clips[:3]] == ["walk", "turn", "jump"]
    scores = action_scores(["walk", "walk", "jump"], [torch.from_numpy(_joints(c)) for c in clips[:3]])
    assert scores["per_action"] == {"walk": [1, 2], "jump": [1, 1]}  # the second clip turns
    assert scores["shown"] == pytest.approx(2 / 3) and scores["read"] == ["walk", "turn", "jump"]
    assert action_checks(scores) == {"paraphrased prompts show their action >= 80%": False}


def test_unknown_kinds_are_refused_when_the_data_module_is_made():
    from skeleton_mamba.tasks.text2motion.data import SyntheticTextMotionDataModule

    with pytest.raises(ValueError, match="unknown clip kinds"):
        SyntheticTextMotionDataModule(kinds=["walk", "moonwalk"])
    assert SyntheticTextMotionDataModule(kinds=["walk", "jump"]).kinds == ("walk", "jump")
