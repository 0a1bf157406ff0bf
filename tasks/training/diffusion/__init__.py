"""The one Gaussian diffusion shared by every generative task (egodance, text2motion).

The API is generic: a *denoiser* is any callable ``(x_t, t, cond) -> x0_hat`` with x_t (B, ...),
t (B,) long timesteps in [0, num_steps) and ``cond`` any condition object, or ``None`` for the
unconditional (null-condition) prediction used by classifier-free guidance. Tasks sample through
:func:`sample` (DDIM or DDPM, :class:`SamplingOptions`), long sequences through :func:`sample_long`.
"""

from skeleton_mamba.tasks.training.diffusion.embedding import sinusoidal_embedding
from skeleton_mamba.tasks.training.diffusion.gaussian import GaussianDiffusion
from skeleton_mamba.tasks.training.diffusion.samplers import (
    GuidanceTerm,
    NullConditioned,
    ddim_sample,
    ddpm_sample,
    guided_x0,
)
from skeleton_mamba.tasks.training.diffusion.sampling import SamplingOptions, sample
from skeleton_mamba.tasks.training.diffusion.schedule import NoiseSchedule, cosine_betas
from skeleton_mamba.tasks.training.diffusion.stitching import (
    WindowConsistency,
    sample_long,
    stitch_windows,
    window_starts,
)

__all__ = [
    "GaussianDiffusion",
    "GuidanceTerm",
    "NoiseSchedule",
    "NullConditioned",
    "SamplingOptions",
    "WindowConsistency",
    "cosine_betas",
    "ddim_sample",
    "ddpm_sample",
    "guided_x0",
    "sample",
    "sample_long",
    "sinusoidal_embedding",
    "stitch_windows",
    "window_starts",
]
