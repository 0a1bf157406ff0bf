"""T2M metrics against hand computations on tiny embeddings, and the evaluator networks."""

from __future__ import annotations

import re

import numpy as np
import pytest
import torch
from scipy import linalg

from skeleton_mamba.errors import CheckpointError
from skeleton_mamba.tasks.text2motion.metrics import (
    Diversity,
    EmbeddingFID,
    MultiModality,
    RPrecision,
    confidence_interval,
    diversity,
    embedding_fid,
    multimodality,
    top_k_hits,
)

# 1-D embeddings: distances are read off by hand.
TEXT = torch.tensor([[0.0], [1.0], [2.0], [3.0]])
MOTION = torch.tensor([[0.1], [2.2], [1.1], [10.0]])
# text 0 -> motions by distance 0, 2, 1, 3: own rank 1; text 1 -> 2, 0, 1: rank 3;
# text 2 -> 1, 2, 0: rank 2; text 3 -> 1, 2, 0, 3: rank 4.


def test_top_k_hits_by_hand():
    hits = top_k_hits(TEXT, MOTION, top_k=3)
    expected = [[1, 1, 1], [0, 0, 1], [0, 1, 1], [0, 0, 0]]
    assert hits.int().tolist() == expected


def test_r_precision_and_mm_dist_with_groups_and_drop_last():
    metric = RPrecision(top_k=3, batch_size=4)
    # two full groups (the second one identical) and one leftover pair that must be dropped
    metric.update(torch.cat([TEXT, TEXT, TEXT[:1]]), torch.cat([MOTION, MOTION, MOTION[3:]]))
    result = metric.compute()
    assert result["top1"].item() == pytest.approx(1 / 4)
    assert result["top2"].item() == pytest.approx(2 / 4)
    assert result["top3"].item() == pytest.approx(3 / 4)
    assert result["mm_dist"].item() == pytest.approx((0.1 + 1.2 + 0.9 + 7.0) / 4)
    with pytest.raises(RuntimeError, match="no complete group"), pytest.warns(UserWarning, match="before"):
        RPrecision(batch_size=32).compute()


def test_fid_by_hand_in_one_dimension_and_against_scipy():
    real = torch.tensor([[0.0], [2.0]])  # mean 1, unbiased variance 2
    generated = torch.tensor([[1.0], [5.0]])  # mean 3, variance 8
    # (3 - 1)^2 + 2 + 8 - 2 sqrt(16) = 6
    assert embedding_fid(real, generated).item() == pytest.approx(6.0)
    metric = EmbeddingFID()
    metric.update(real, real=True)
    metric.update(generated, real=False)
    assert metric.compute().item() == pytest.approx(6.0)

    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(40, 5)), rng.normal(1.0, 2.0, size=(30, 5))
    s1, s2 = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    covmean = linalg.sqrtm(s1 @ s2).real
    expected = ((a.mean(0) - b.mean(0)) ** 2).sum() + np.trace(s1 + s2 - 2 * covmean)
    assert embedding_fid(torch.from_numpy(a), torch.from_numpy(b)).item() == pytest.approx(expected, rel=1e-8)


def test_diversity_and_multimodality_follow_the_drawn_pairs():
    emb = torch.randn(12, 3, dtype=torch.float64)
    value = diversity(emb, times=5, generator=torch.Generator().manual_seed(7))
    g = torch.Generator().manual_seed(7)
    first, second = torch.randperm(12, generator=g)[:5].tolist(), torch.randperm(12, generator=g)[:5].tolist()
    by_hand = sum(float(np.linalg.norm(emb[i] - emb[j])) for i, j in zip(first, second, strict=True)) / 5
    assert value.item() == pytest.approx(by_hand)
    assert len(set(first)) == 5  # without replacement
    with pytest.raises(ValueError, match="at least 300"):
        diversity(emb)

    gen = torch.randn(4, 6, 3, dtype=torch.float64)
    value = multimodality(gen, times=3, generator=torch.Generator().manual_seed(3))
    g = torch.Generator().manual_seed(3)
    first, second = torch.randperm(6, generator=g)[:3].tolist(), torch.randperm(6, generator=g)[:3].tolist()
    pairs = [(t, i, j) for t in range(4) for i, j in zip(first, second, strict=True)]
    by_hand = sum(float(np.linalg.norm(gen[t, i] - gen[t, j])) for t, i, j in pairs) / len(pairs)
    assert value.item() == pytest.approx(by_hand)


def test_diversity_of_gaussian_embeddings_is_about_sqrt_2d():
    # E|x - y| for x, y ~ N(0, I_64) is close to sqrt(2 * 64) = 11.3.
    torch.manual_seed(0)
    metric = Diversity(times=300, seed=0)
    metric.update(torch.randn(600, 64))
    assert metric.compute().item() == pytest.approx(11.3, abs=0.3)
    mm = MultiModality(times=10, seed=0)
    mm.update(torch.zeros(5, 30, 8))  # identical generations: no multimodality
    assert mm.compute().item() == 0.0


def test_confidence_interval_by_hand():
    mean, half = confidence_interval(torch.tensor([1.0, 2.0, 3.0, 4.0]))
    # population std of 1..4 is sqrt(1.25)
    assert mean.item() == 2.5 and half.item() == pytest.approx(1.96 * 1.25**0.5 / 2)


def test_evaluator_parameter_names_match_the_official_checkpoint_layout(tmp_path):
    from skeleton_mamba.tasks.text2motion.evaluator import T2MEvaluator

    sizes = dict(text_hidden=8, movement_hidden=8, movement_latent=8, motion_hidden=8, embedding_dim=4)
    model = T2MEvaluator(**sizes)
    gru = [f"gru.{k}_{d}_l0{s}" for k in ("weight", "bias") for d in ("ih", "hh") for s in ("", "_reverse")]
    head = [f"output_net.{i}.{p}" for i in (0, 1, 3) for p in ("weight", "bias")]
    linear = [f"{n}.{p}" for n in ("pos_emb", "input_emb") for p in ("weight", "bias")]
    assert set(model.text_encoder.state_dict()) == {*linear, *gru, *head, "hidden"}
    assert set(model.motion_encoder.state_dict()) == {*linear[2:], *gru, *head, "hidden"}
    assert set(model.movement_encoder.state_dict()) == {
        f"{n}.{p}" for n in ("main.0", "main.3", "out_net") for p in ("weight", "bias")
    }
    # the official file: the three state dicts beside optimiser states and counters
    keys = ("text_encoder", "movement_encoder", "motion_encoder")
    state = {k: getattr(model, k).state_dict() for k in keys}
    torch.save({**state, "epoch": 12, "it": 3400}, tmp_path / "finest.tar")
    loaded = T2MEvaluator.from_checkpoint(tmp_path / "finest.tar", **sizes)
    assert loaded.comparable and not model.comparable
    torch.testing.assert_close(loaded.motion_encoder.hidden, model.motion_encoder.hidden)
    torch.save({"text_encoder": state["text_encoder"]}, tmp_path / "bad.tar")
    with pytest.raises(CheckpointError, match="bad.tar: no 'movement_encoder'"):
        T2MEvaluator.from_checkpoint(tmp_path / "bad.tar", **sizes)
    # Wrong shapes and non-finite weights: one line naming the file, the part and the first mismatch.
    wrong = {**state, "motion_encoder": {**state["motion_encoder"], "hidden": torch.zeros(3, 5)}}
    torch.save(wrong, tmp_path / "wrong.tar")
    shape = tuple(state["motion_encoder"]["hidden"].shape)
    message = r"wrong.tar \[motion_encoder\]: does not fit .*hidden has shape \(3, 5\) in the checkpoint, "
    with pytest.raises(CheckpointError, match=message + rf"{re.escape(str(shape))} in the model"):
        T2MEvaluator.from_checkpoint(tmp_path / "wrong.tar", **sizes)
    nan = {k: dict(v) for k, v in state.items()}
    nan["text_encoder"]["hidden"] = torch.full_like(state["text_encoder"]["hidden"], float("nan"))
    torch.save(nan, tmp_path / "nan.tar")
    with pytest.raises(CheckpointError, match=r"nan.tar \[text_encoder\]: .*not finite \(hidden"):
        T2MEvaluator.from_checkpoint(tmp_path / "nan.tar", **sizes)


def test_evaluator_embeddings_ignore_extra_padding_and_keep_input_order():
    from skeleton_mamba.tasks.text2motion.evaluator import T2MEvaluator

    torch.manual_seed(0)
    model = T2MEvaluator().eval()
    # Zero padding as the dataset pads (to 196): the convolutions see up to 6 frames past the end, so
    # the embedding is the same for any padding of at least that much.
    motions = torch.randn(3, 48, 263)
    lengths = torch.tensor([24, 40, 32])
    for i, n in enumerate(lengths.tolist()):
        motions[i, n:] = 0
    with torch.no_grad():
        short = model.embed_motion(motions, lengths)
        long = model.embed_motion(torch.cat([motions, torch.zeros(3, 20, 263)], dim=1), lengths)
        alone = model.embed_motion(motions[2:, :40], lengths[2:])
    assert short.shape == (3, 512)
    torch.testing.assert_close(short, long, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(short[2:], alone, atol=1e-5, rtol=1e-5)
    words, pos = torch.randn(2, 22, 300), torch.zeros(2, 22, 15)
    with torch.no_grad():
        text = model.embed_text(words, pos, torch.tensor([5, 9]))
        first = model.embed_text(words[:1, :5], pos[:1, :5], torch.tensor([5]))
    torch.testing.assert_close(text[:1], first, atol=1e-5, rtol=1e-5)


def test_word_vectorizer_reads_glove_files_and_applies_vip_and_unknown_rules(tmp_path):
    import pickle

    from skeleton_mamba.tasks.text2motion.glove import WordVectorizer, pad_tokens

    words = ["unk", "sos", "eos", "person", "walk", "left"]
    np.save(tmp_path / "our_vab_data.npy", np.arange(18, dtype=np.float32).reshape(6, 3))
    (tmp_path / "our_vab_words.pkl").write_bytes(pickle.dumps(words))
    (tmp_path / "our_vab_idx.pkl").write_bytes(pickle.dumps({w: i for i, w in enumerate(words)}))
    vectorizer = WordVectorizer(tmp_path)
    vector, pos = vectorizer["walk/VERB"]
    assert vector.tolist() == [12, 13, 14] and pos.argmax() == 12  # Act_VIP overrides VERB
    vector, pos = vectorizer["left/ADV"]
    assert pos.argmax() == 9  # Loc_VIP
    vector, pos = vectorizer["person/NOUN"]
    assert pos.argmax() == 1
    vector, pos = vectorizer["zebra/NOUN"]
    assert vector.tolist() == [0, 1, 2] and pos.argmax() == 14  # unk / OTHER
    tokens, length = pad_tokens(["a/DET", "person/NOUN"])
    assert length == 4 and len(tokens) == 22
    assert tokens[:5] == ["sos/OTHER", "a/DET", "person/NOUN", "eos/OTHER", "unk/OTHER"]
    tokens, length = pad_tokens([f"w{i}/NOUN" for i in range(25)])
    assert length == 22 and tokens[-2] == "w19/NOUN" and tokens[-1] == "eos/OTHER"
    embs, onehots, length = vectorizer.encode(["person/NOUN"])
    assert embs.shape == (22, 3) and onehots.shape == (22, 15) and length == 3
    with pytest.raises(FileNotFoundError, match="missing GloVe file"):
        WordVectorizer(tmp_path, prefix="other")


def test_contrastive_loss_by_hand():
    from skeleton_mamba.tasks.text2motion.evaluator_module import contrastive_loss

    a = torch.tensor([[0.0, 0.0], [0.0, 0.0]])
    b = torch.tensor([[3.0, 4.0], [6.0, 8.0]])  # distances 5 and 10
    # positives: mean(d^2) = (25 + 100) / 2; negatives with margin 10: mean(max(0, 10 - d)^2) = (25 + 0) / 2
    assert contrastive_loss(a, b, torch.zeros(2), 10.0).item() == pytest.approx(62.5, rel=1e-6)
    assert contrastive_loss(a, b, torch.ones(2), 10.0).item() == pytest.approx(12.5, rel=1e-6)


def test_evaluator_trains_one_step_through_sm(tmp_path, monkeypatch):
    import pickle

    from skeleton_mamba.tasks.training.cli import main

    root, glove = tmp_path / "humanml3d", tmp_path / "glove"
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    glove.mkdir()
    rng = np.random.default_rng(0)
    for i in range(1, 3):
        np.save(root / "new_joint_vecs" / f"00000{i}.npy", rng.normal(size=(44, 263)).astype(np.float32))
        (root / "texts" / f"00000{i}.txt").write_text("a person walks.#a/DET person/NOUN walk/VERB#0.0#0.0\n")
    np.save(root / "Mean.npy", np.zeros(263, np.float32))
    np.save(root / "Std.npy", np.ones(263, np.float32))
    (root / "train.txt").write_text("000001\n000002\n")
    (root / "val.txt").write_text("000001\n000002\n")
    words = ["unk", "sos", "eos", "a", "person", "walk"]
    np.save(glove / "our_vab_data.npy", rng.normal(size=(6, 300)).astype(np.float32))
    (glove / "our_vab_words.pkl").write_bytes(pickle.dumps(words))
    (glove / "our_vab_idx.pkl").write_bytes(pickle.dumps({w: i for i, w in enumerate(words)}))
    monkeypatch.chdir(tmp_path)
    args = ["fit", "--recipe", "t2m_evaluator.yaml", "--trainer.max_steps", "1", "--trainer.logger", "false"]
    args += ["--trainer.callbacks", "[]", "--trainer.enable_progress_bar", "false"]
    args += ["--trainer.accelerator", "cpu"]
    args += ["--data.root", str(root), "--data.glove_dir", str(glove), "--data.batch_size", "2"]
    args += ["--data.num_workers", "0", "--trainer.limit_val_batches", "0"]
    assert main(args) == 0
    (checkpoint,) = (tmp_path / "checkpoints").glob("*.ckpt")
    from skeleton_mamba.tasks.text2motion.evaluator import load_evaluator

    evaluator = load_evaluator(checkpoint)  # `sm test --model.evaluator_checkpoint best.ckpt` reads it so
    assert not evaluator.comparable and evaluator.motion_encoder.hidden.shape == (2, 1, 1024)
