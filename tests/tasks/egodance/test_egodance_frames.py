"""Frame resizing for the EMM's vision inputs: values, antialiasing, and the contiguous layout."""

import pytest
import torch

from skeleton_mamba.tasks.egodance.frames import resize_frames


def _channels_last(images: torch.Tensor) -> torch.Tensor:
    """(N, 3, H, W) with the memory layout of decoded video permuted from (N, H, W, 3)."""
    return images.permute(0, 2, 3, 1).contiguous().permute(0, 3, 1, 2)


def test_same_size_keeps_the_values_and_makes_channels_last_frames_contiguous():
    images = _channels_last(torch.rand(5, 3, 12, 12))
    assert not images.is_contiguous()
    out = resize_frames(images, 12)
    assert out.is_contiguous() and torch.equal(out, images)


def test_shrinking_is_antialiased_and_exact_on_a_linear_ramp():
    # A pixel-level checkerboard has no content below the new Nyquist limit: antialiased shrinking by 2
    # must give flat grey (plain bilinear sampling at the new pixel centres would alias it).
    y, x = torch.meshgrid(torch.arange(32), torch.arange(32), indexing="ij")
    board = ((x + y) % 2).float().expand(2, 3, 32, 32)
    out = resize_frames(_channels_last(board.contiguous()), 16)
    assert out.shape == (2, 3, 16, 16) and out.is_contiguous()
    torch.testing.assert_close(out[..., 1:-1, 1:-1], torch.full_like(out[..., 1:-1, 1:-1], 0.5))
    # A linear ramp is reproduced exactly at the new pixel centres (x' = 2 i + 0.5 in input pixels),
    # away from the border where the filter is renormalised.
    ramp = x.double().expand(1, 3, 32, 32)
    out = resize_frames(ramp, (32, 16))
    centres = 2 * torch.arange(16, dtype=torch.float64) + 0.5
    torch.testing.assert_close(out[0, 0, :, 1:-1], centres[1:-1].expand(32, 14))


def test_growing_is_bilinear_and_bad_shapes_are_refused():
    images = torch.rand(2, 3, 8, 8)
    torch.testing.assert_close(
        resize_frames(images, 16),
        torch.nn.functional.interpolate(images, size=(16, 16), mode="bilinear", align_corners=False),
    )
    with pytest.raises(ValueError, match=r"\(N, C, H, W\)"):
        resize_frames(torch.rand(3, 8, 8), 4)


def test_vision_encoder_feeds_its_resnet_contiguous_frames():
    # oneDNN's convolution backward corrupted the heap on channels-last input (torch 2.13, CPU).
    from transformers import ResNetConfig

    from skeleton_mamba.tasks.egodance.encoders import VisionEncoder

    config = ResNetConfig(embedding_size=8, hidden_sizes=[8], depths=[1], layer_type="basic")
    with pytest.warns(UserWarning, match="randomly initialised"):
        encoder = VisionEncoder(
            16, resnet_config=config, image_size=16, freeze=False, chunk_pixels=4 * 16 * 16
        )
    seen = []
    encoder.resnet.register_forward_pre_hook(
        lambda module, args, kwargs: seen.append(kwargs["pixel_values"].is_contiguous()), with_kwargs=True
    )
    frames = _channels_last(torch.rand(6, 3, 16, 16)).reshape(2, 3, 3, 16, 16)
    assert not frames.flatten(0, 1).is_contiguous()
    features = encoder(frames)
    features.square().sum().backward()
    assert features.shape == (2, 3, 16) and seen == [True, True]
    expected = encoder(frames.contiguous())
    torch.testing.assert_close(features, expected)


def test_vision_encoder_calls_its_resnet_per_pixel_budget():
    """64 frames of 224 px per ResNet call (the paper's size), a demo batch of 32 px frames in one call; in
    training mode the output is the ResNet over all frames of the call at once (BatchNorm statistics)."""
    from transformers import ResNetConfig

    from skeleton_mamba.tasks.egodance.encoders import VisionEncoder

    config = ResNetConfig(embedding_size=8, hidden_sizes=[8, 16], depths=[1, 1], layer_type="basic")
    with pytest.warns(UserWarning, match="randomly initialised"):
        paper = VisionEncoder(16, resnet_config=config, image_size=224)
        demo = VisionEncoder(16, resnet_config=config, image_size=32, freeze=False)
    assert paper.chunk == 64 and demo.chunk >= 4 * 150
    frames = torch.rand(4, 150, 3, 32, 32)
    calls = []
    demo.resnet.register_forward_pre_hook(
        lambda m, a, k: calls.append(len(k["pixel_values"])), with_kwargs=True
    )
    demo.train()
    features = demo(frames)
    assert calls == [600]
    flat = demo.normalize(frames.flatten(0, 1))  # 32 px frames: no resize
    pooled = demo.resnet(pixel_values=flat).pooler_output.flatten(1)  # every frame's BatchNorm statistics
    torch.testing.assert_close(features, demo.mlp(pooled).reshape(4, 150, 16))


def test_data_set_frames_are_contiguous(tmp_path):
    from skeleton_mamba.tasks.egodance.data import SyntheticEgoDanceDataModule

    data = SyntheticEgoDanceDataModule(
        root=str(tmp_path / "data"), count=1, duration_s=5.0, frame_size=16, image_size=8,
        val_fraction=0.0, test_fraction=0.0, music_cache_dir=str(tmp_path / "cache"),
    )  # fmt: skip
    data.prepare_data()
    data.setup("fit")
    frames = data.datasets["train"][0]["frames"]
    assert frames.shape == (150, 3, 8, 8) and frames.is_contiguous()
    assert 0.0 <= float(frames.min()) and float(frames.max()) <= 1.0


def test_frozen_vision_encoder_runs_channels_last_and_bf16_as_a_kept_copy():
    """Inference: channels-last activations give the NCHW features (to fp32 rounding); under bf16 autocast
    (``--precision bf16``) a bfloat16 copy of the frozen ResNet runs, close to fp32, outside the state
    dict, and rebuilt when the weights are loaded again."""
    from transformers import ResNetConfig

    from skeleton_mamba.tasks.egodance.encoders import VisionEncoder

    torch.manual_seed(0)
    config = ResNetConfig(embedding_size=8, hidden_sizes=[8, 16], depths=[1, 1], layer_type="basic")
    with pytest.warns(UserWarning, match="randomly initialised"):
        encoder = VisionEncoder(16, resnet_config=config, image_size=32).eval()
    layouts = []
    encoder.resnet.register_forward_pre_hook(
        lambda m, a, k: layouts.append(k["pixel_values"].is_contiguous(memory_format=torch.channels_last)),
        with_kwargs=True,
    )
    frames = torch.rand(1, 5, 3, 32, 32)
    with torch.no_grad():
        features = encoder(frames)
        flat = encoder.normalize(frames.flatten(0, 1)).contiguous()  # NCHW, computed independently
        expected = encoder.mlp(encoder.resnet(pixel_values=flat).pooler_output.flatten(1)).reshape(1, 5, 16)
        torch.testing.assert_close(features, expected, rtol=1e-5, atol=1e-6)
        assert layouts[0] is True
        keys = set(encoder.state_dict())
        with torch.autocast("cpu", dtype=torch.bfloat16):
            low = encoder(frames).float()
        copy = encoder.__dict__["_bf16_resnet"][1]
        assert set(encoder.state_dict()) == keys and next(copy.parameters()).dtype == torch.bfloat16
        assert layouts == [True, False, True]  # the copy (its hook copied along) ran, channels-last
        cos = torch.nn.functional.cosine_similarity(low.flatten(), expected.flatten(), dim=0)
        assert cos > 0.999 and not torch.equal(low, expected)
        first = copy
        encoder.resnet.load_state_dict({k: v + 0.01 for k, v in encoder.resnet.state_dict().items()})
        with torch.autocast("cpu", dtype=torch.bfloat16):
            encoder(frames)
        assert encoder.__dict__["_bf16_resnet"][1] is not first
