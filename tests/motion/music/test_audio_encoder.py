"""The pretrained audio encoder, on a tiny random wav2vec2 saved to and loaded back from a local folder."""

from __future__ import annotations

import numpy as np
import pytest
import soundfile as sf
import torch

from skeleton_mamba.tasks.motion.music.audio_encoder import PretrainedAudioEncoder, resample_frames

SR = 16000


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """A randomly initialised 2-layer wav2vec2 (hidden 16) and its feature extractor, saved locally."""
    from transformers import Wav2Vec2Config, Wav2Vec2FeatureExtractor, Wav2Vec2Model

    torch.manual_seed(0)
    config = Wav2Vec2Config(
        hidden_size=16, num_hidden_layers=2, num_attention_heads=2, intermediate_size=32,
        conv_dim=(16,) * 7, num_conv_pos_embeddings=16, num_conv_pos_embedding_groups=2,
    )  # fmt: skip
    folder = tmp_path_factory.mktemp("tiny_wav2vec2")
    Wav2Vec2Model(config).save_pretrained(folder)
    Wav2Vec2FeatureExtractor(sampling_rate=SR).save_pretrained(folder)
    return folder


@pytest.fixture(scope="module")
def direct(checkpoint):
    """The same checkpoint loaded directly through transformers (model, feature extractor)."""
    from transformers import Wav2Vec2FeatureExtractor, Wav2Vec2Model

    model = Wav2Vec2Model.from_pretrained(checkpoint).eval()
    return model, Wav2Vec2FeatureExtractor.from_pretrained(checkpoint)


def direct_hidden(direct, audio: np.ndarray, layer: int | None = None) -> np.ndarray:
    """Hidden states ``(N, D)`` from the model run directly through transformers."""
    model, extractor = direct
    inputs = extractor(audio, sampling_rate=SR, return_tensors="pt")
    with torch.no_grad():
        out = model(**inputs, output_hidden_states=True)
    return (out.last_hidden_state if layer is None else out.hidden_states[layer])[0].numpy()


def interp_to(frames: np.ndarray, t_out: int) -> np.ndarray:
    """Linear resampling with frame centres at ``(j + 0.5) N / T - 0.5`` (clamped at the ends)."""
    n = len(frames)
    x = (np.arange(t_out) + 0.5) * n / t_out - 0.5
    return np.stack([np.interp(x, np.arange(n), frames[:, d]) for d in range(frames.shape[1])], axis=1)


def test_output_shape_and_values_match_transformers(checkpoint, direct):
    audio = np.random.default_rng(0).normal(scale=0.1, size=SR).astype(np.float32)
    encoder = PretrainedAudioEncoder(str(checkpoint), fps=30, chunk_seconds=None)
    out = encoder(audio)
    assert out.shape == (30, 16) and encoder.embedding_dim == 16
    expected = interp_to(direct_hidden(direct, audio), 30)
    np.testing.assert_allclose(out.numpy(), expected, rtol=1e-4, atol=1e-5)
    encoder.layer = 1  # hidden_states[1]: after the first transformer layer
    expected = interp_to(direct_hidden(direct, audio, 1), 45)
    np.testing.assert_allclose(encoder(audio, num_frames=45).numpy(), expected, rtol=1e-4, atol=1e-5)


def test_chunking_concatenates_pieces(checkpoint, direct):
    audio = np.random.default_rng(1).normal(scale=0.1, size=SR).astype(np.float32)
    encoder = PretrainedAudioEncoder(str(checkpoint), fps=30, chunk_seconds=0.5)
    half = SR // 2
    pieces = np.concatenate([direct_hidden(direct, audio[:half]), direct_hidden(direct, audio[half:])])
    np.testing.assert_allclose(encoder(audio).numpy(), interp_to(pieces, 30), rtol=1e-4, atol=1e-5)


def test_resample_frames_hand_values():
    frames = torch.tensor([[0.0], [2.0]])
    # 2 -> 4 frames: centres at -0.25, 0.25, 0.75, 1.25 in source index -> clamp/linear -> 0, 0.5, 1.5, 2
    np.testing.assert_allclose(resample_frames(frames, 4)[:, 0].numpy(), [0.0, 0.5, 1.5, 2.0])
    with pytest.raises(ValueError):
        resample_frames(frames, 0)


def test_frozen_encoder_and_other_sample_rates(checkpoint):
    encoder = PretrainedAudioEncoder(str(checkpoint), fps=60)
    assert not any(p.requires_grad for p in encoder.parameters())
    encoder.train()
    assert not encoder.model.training
    out = encoder.encode(np.zeros(22050, dtype=np.float32), sr=22050)  # 1 s at 22.05 kHz
    assert out.shape == (60, 16)


def test_encode_file_uses_the_cache(checkpoint, tmp_path, monkeypatch):
    wav = tmp_path / "noise.wav"
    sf.write(wav, np.random.default_rng(2).normal(scale=0.1, size=SR).astype(np.float32), SR)
    encoder = PretrainedAudioEncoder(str(checkpoint), fps=30)
    first = encoder.encode_file(wav, cache_dir=tmp_path / "cache")
    assert first.shape == (30, 16)
    assert len(list((tmp_path / "cache").glob("*.npy"))) == 1

    def no_forward(*args, **kwargs):
        raise AssertionError("expected a cache hit")

    monkeypatch.setattr(encoder, "_encode_piece", no_forward)
    again = encoder.encode_file(wav, cache_dir=tmp_path / "cache")
    np.testing.assert_array_equal(again.numpy(), first.numpy())


def test_bad_checkpoint_folders(tmp_path, checkpoint):
    with pytest.raises(FileNotFoundError, match="config.json"):
        PretrainedAudioEncoder(str(tmp_path / "nothing"))
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "config.json").write_text((checkpoint / "config.json").read_text())
    with pytest.raises(ValueError, match="broken"):
        PretrainedAudioEncoder(str(broken))
