"""Compiled SSD and EMM denoiser (skeleton_mamba/runtime/compiling.py): the eager results to fp32 rounding.

Inductor on a CPU compiles generated C++: without a C++ compiler the tests skip.
"""

from __future__ import annotations

import shutil

import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.runtime.compiling import compile_for_inference
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
def test_compiled_ssd_equals_the_float64_recurrence():
    """Compiled, the SSD runs its matrix form without the data-dependent finiteness branch."""
    torch._dynamo.reset()
    compiled = compile_for_inference(ssd_quadratic)
    inp = _ssd_inputs()
    with torch.inference_mode():
        got = compiled(**inp)
        ref = ssd_recurrence(**{k: v.double() for k, v in inp.items()})
    torch.testing.assert_close(got.double(), ref, rtol=1e-5, atol=1e-5)


@pytest.mark.slow  # inductor compiles C++
def test_compiled_chunked_ssd_trains_like_eager():
    """Under torch.compile the chunked form's ChunkScan runs eagerly (a graph break around it): outputs,
    final state and every gradient equal the eager ones."""
    from skeleton_mamba.ssd.chunked import ssd_chunked

    torch._dynamo.reset()
    inp = _ssd_inputs(L=40)  # 5 chunks of 8
    results = []
    for fn in (ssd_chunked, torch.compile(ssd_chunked)):
        leaves = {k: v.clone().requires_grad_(True) for k, v in inp.items()}
        y, final = fn(**leaves, chunk_size=8, return_final_state=True)
        (y.square().sum() + final.sum()).backward()
        results.append((y.detach(), final.detach(), {k: v.grad for k, v in leaves.items()}))
    (y0, f0, g0), (y1, f1, g1) = results
    torch.testing.assert_close(y1, y0, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(f1, f0, rtol=1e-5, atol=1e-5)
    for k in inp:
        torch.testing.assert_close(g1[k], g0[k], rtol=1e-4, atol=1e-4, msg=lambda m, k=k: f"grad {k}: {m}")


@pytest.mark.slow  # compiling even a one-block EMM takes about a minute on 2 CPU cores
def test_compiled_emm_denoiser_equals_eager():
    from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig

    torch._dynamo.reset()
    torch.manual_seed(0)
    backbone = SkeletonMambaConfig(
        dim=16,
        depth=1,
        heads=2,
        mlp_dim=32,
        mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16),
        cpu_slice_elements=2048,  # eager runs in slices of frames; compiled in one call
    )
    model = EMM(backbone, EMMConfig(context_dim=16, use_vision=False, heads=2, transformer_ff=32)).eval()
    x, t = torch.randn(2, 12, 24, 10), torch.tensor([3, 700])
    with torch.inference_mode():
        context = model.encode_condition(torch.randn(2, 12, 35))
        eager = model(x, t, context)
        got = compile_for_inference(model)(x, t, context)
    assert torch.isfinite(eager).all()
    torch.testing.assert_close(got, eager, rtol=1e-4, atol=1e-5)


@pytest.mark.slow  # compiles a one-block EMM: about a minute on 2 CPU cores
def test_sample_dance_compiled_equals_eager():
    from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
    from skeleton_mamba.tasks.egodance.sampling import sample_dance
    from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion

    torch._dynamo.reset()
    torch.manual_seed(1)
    backbone = SkeletonMambaConfig(
        dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    model = EMM(backbone, EMMConfig(context_dim=16, use_vision=False, heads=2, transformer_ff=32)).eval()
    diffusion, music = GaussianDiffusion(10), torch.randn(2, 12, 35)
    options = dict(sampler="ddim", sampling_steps=3, guidance_weight=2.0)
    eager = sample_dance(model, diffusion, music, generator=torch.Generator().manual_seed(3), **options)
    got = sample_dance(
        model, diffusion, music, generator=torch.Generator().manual_seed(3), compile=True, **options
    )
    assert eager.shape == (2, 12, 24, 10) and torch.isfinite(eager).all()
    torch.testing.assert_close(got, eager, rtol=1e-4, atol=1e-5)
