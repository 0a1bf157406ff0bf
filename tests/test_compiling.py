"""Compiled inference (skeleton_mamba/compiling.py) gives the eager results to float32 rounding.

Inductor on a CPU compiles generated C++: without a C++ compiler the tests skip.
"""

from __future__ import annotations

import shutil

import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.compiling import compile_for_inference
from skeleton_mamba.ssd.quadratic import ssd_quadratic
from skeleton_mamba.ssd.recurrence import ssd_recurrence

pytestmark = pytest.mark.skipif(
    shutil.which("c++") is None and shutil.which("g++") is None,
    reason="torch.compile (inductor) on a CPU needs a C++ compiler; none on PATH",
)


def _ssd_inputs(L: int = 12, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    b, H, P, G, N = 2, 4, 4, 2, 3
    return dict(
        x=torch.randn(b, L, H, P, generator=g),
        dt=torch.randn(b, L, H, generator=g),
        A=-torch.rand(H, generator=g) * 4 - 0.5,
        B=torch.randn(b, L, G, N, generator=g),
        C=torch.randn(b, L, G, N, generator=g),
        D=torch.randn(H, generator=g),
        dt_bias=torch.randn(H, generator=g) * 0.1,
    )


@pytest.mark.slow  # inductor compiles C++: about 40 s of CPU
def test_compiled_ssd_confines_non_finite_inputs_like_the_recurrence():
    """Compiled, the SSD has no data-dependent branch: it runs the confining path on every input, which
    must equal the float64 recurrence on finite inputs and keep a NaN to the steps at and after it."""
    torch._dynamo.reset()
    compiled = compile_for_inference(ssd_quadratic)
    clean = _ssd_inputs()
    bad = {k: v.clone() for k, v in clean.items()}
    bad["x"][1, 5, 2, 1] = float("nan")  # batch 1, step 5, head 2, channel 1
    with torch.inference_mode():
        for inp in (clean, bad):
            got = compiled(**inp)
            ref = ssd_recurrence(**{k: v.double() for k, v in inp.items()})
            finite = torch.isfinite(ref)
            torch.testing.assert_close(got.double()[finite], ref[finite], rtol=1e-5, atol=1e-5)
            assert torch.equal(torch.isfinite(got), finite)
    nan = torch.isnan(got)
    assert nan[1, 5:, 2, 1].all() and nan.sum() == 12 - 5  # that channel from step 5 on, nothing else


@pytest.mark.slow  # compiling even a one-block EMM takes about a minute on 2 CPU cores
def test_compiled_dance_sampling_equals_eager():
    from skeleton_mamba.tasks.diffusion import GaussianDiffusion
    from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
    from skeleton_mamba.tasks.egodance.sampling import sample_dance

    torch._dynamo.reset()
    torch.manual_seed(0)
    backbone = SkeletonMambaConfig(
        dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    model = EMM(backbone, EMMConfig(context_dim=16, use_vision=False, heads=2, transformer_ff=32)).eval()
    diffusion = GaussianDiffusion(10)
    music = torch.randn(2, 12, 35)
    options = dict(sampler="ddim", sampling_steps=3, guidance_weight=2.0)
    eager = sample_dance(model, diffusion, music, generator=torch.Generator().manual_seed(3), **options)
    compiled = sample_dance(
        model, diffusion, music, generator=torch.Generator().manual_seed(3), compile=True, **options
    )
    assert eager.shape == (2, 12, 24, 10) and torch.isfinite(eager).all()
    torch.testing.assert_close(compiled, eager, rtol=1e-4, atol=1e-5)
