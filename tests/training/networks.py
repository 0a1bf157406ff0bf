"""Tiny networks of every task, for the pretrained-folder tests."""

from __future__ import annotations

import math
import warnings

import torch

from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig

MIXER = MixerConfig(d_state=8, headdim=8, chunk_size=16, dt_limit=(0.0, math.inf), A_init_range=(1.0, 8.0))


TINY = SkeletonMambaConfig(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MIXER)


def _networks():
    """(name, network, inputs of its forward) for the backbone and every task network, tiny and random."""
    from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
    from skeleton_mamba.tasks.qean.model import QEAN, QEANConfig
    from skeleton_mamba.tasks.recognition.model import ActionRecognizer
    from skeleton_mamba.tasks.stream.model import StreamDancer
    from skeleton_mamba.tasks.text2motion.model import TextToMotionDenoiser

    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    ntu = SkeletonMambaConfig(
        skeleton="ntu25", in_channels=3, dim=16, depth=1, heads=2, mlp_dim=32, mixer=MIXER
    )
    resnet = {"embedding_size": 8, "hidden_sizes": [8, 16], "depths": [1, 1], "layer_type": "basic"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the tiny ResNet is random
        emm = EMM(
            TINY, EMMConfig(context_dim=16, resnet_layers=resnet, heads=2, transformer_ff=32), image_size=32
        )
    emm.set_data_statistics(
        torch.randn(2, 8, 24, 10, generator=g) * 3 + 1, torch.randn(2, 8, 35, generator=g)
    )
    qean_cfg = QEANConfig(
        hidden=16, heads=2, motion_layers=1, audio_layers=1, cross_layers=1, mlp_dim=32, seed_frames=8,
        music_frames=16, predict_frames=4,
    )  # fmt: skip
    qean = QEAN(qean_cfg, SkeletonMambaConfig(dim=8, depth=1, heads=2, mlp_dim=16, mixer=MIXER))
    t2m = TextToMotionDenoiser(TINY, text_dim=12, time_channels=4, time_embedding_dim=16, diffusion_steps=20)
    t2m.set_data_statistics(torch.randn(50, 263, generator=g) * 2)
    dancer = StreamDancer(TINY, music_dim=6)
    dancer.set_music_statistics(torch.randn(40, 6, generator=g) * 5 + 2)
    t = torch.tensor([3, 7])
    return [
        ("SkeletonMamba", SkeletonMamba(ntu), (torch.randn(2, 9, 25, 3, generator=g),)),
        ("EMM", emm, (torch.randn(2, 8, 24, 10, generator=g), t, torch.randn(2, 8, 16, generator=g))),
        ("QEAN", qean, (torch.randn(2, 8, 219, generator=g), torch.randn(2, 16, 35, generator=g))),
        (
            "ActionRecognizer",
            ActionRecognizer(ntu, num_classes=5),
            (torch.randn(2, 2, 9, 25, 3, generator=g),),
        ),
        ("TextToMotionDenoiser", t2m, (torch.randn(2, 8, 263, generator=g), t)),
        ("StreamDancer", dancer, (torch.randn(2, 8, 24, 12, generator=g), torch.randn(2, 8, 6, generator=g))),
    ]
