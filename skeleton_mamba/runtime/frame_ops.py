"""Inference operations for one frame of a stream: the frame-wise scans' projections and mixers.

In a stream, every frame runs the Group Scan (one sequence of n·G = 40 group tokens per stream) and
the Joint Scan (G sequences of P = 6 joint tokens) from a zero state. :class:`FrameOps` is what
:meth:`SkeletonMambaBlock.spatial` uses then instead of the modules' own calls:

- :func:`linear`: a Linear on a few tokens. The step of the seed-size model is bound by reading its
  weights (about 150 MB per frame, most of it the Group Scan's projections, each applied to 5
  tokens). oneDNN's inner product reads a (out, in) weight faster than the default CPU GEMM at
  such shapes, so the large fp32 projections go through it; small ones and other dtypes stay on
  ``F.linear``, as fast or faster there.
- :func:`short_mix`: at such sizes the cost of the sequence path (:meth:`Mamba2Mixer.mix`:
  autograd functions, tiling, the finiteness check of the SSD matrix forms) is the number of
  operations, not arithmetic. It computes the same quantity, ``mixer.mix(zxbcdt)``, by the
  quadratic SSD form in one block with no autograd machinery ([Mamba-2] SSD, "attention-like"
  form), per head h of B/C group g:

    y = (Lmask ∘ C Bᵀ)(Δ ⊙ x) + D ⊙ x,    Lmask_ij = exp(cs_i - cs_j) for i ≥ j, else 0,

  with cs the inclusive cumulative sum of Δ·A, formed in float64 (|cs| reaches the hundreds: an fp32
  cs would put an error of u·|cs| on the mask), so the mask is exact to the compute dtype's rounding.

Inference only (no autograd), cost O(L²) per head: meant for L up to a few dozen. A non-finite
token makes the whole sequence's output non-finite (the matrix form multiplies it by the zeros of
the mask), where the sequence path confines it to the later tokens
(``skeleton_mamba/ssd/non_finite.py``). In a frame this changes nothing: the Group Scan's
un-permuting average mixes every path position into every group, so one NaN joint makes the whole
frame NaN either way.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from skeleton_mamba.causal_conv import causal_conv_taps
from skeleton_mamba.ssd.discretize import compute_dtype, discretize_dt
from skeleton_mamba.ssd.exportable import masked_quadratic
from skeleton_mamba.ssd.precision import full_precision

# Weights of at least this many entries go through oneDNN (fp32 on CPU): the Group Scan's in_proj
# and out_proj and the Joint Scan's split at the paper width; below it F.linear was as fast or faster.
ONEDNN_MIN_WEIGHT = 1 << 19
_ONEDNN = torch.backends.mkldnn.is_available() and hasattr(torch.ops.mkldnn, "_linear_pointwise")


def linear(layer: nn.Linear, x: torch.Tensor) -> torch.Tensor:
    """``layer(x)`` for a few tokens x (..., in) at inference; oneDNN for large fp32 CPU weights, the layer's
    own call for a dynamically quantized int8 Linear (``sm stream --quantize int8``).

    Under ``torch.compile`` always ``F.linear``: inductor cannot lower the eager oneDNN call, and with
    frozen weights it packs them for oneDNN itself (:mod:`skeleton_mamba.runtime.compiling`).
    """
    w = layer.weight
    if not isinstance(w, torch.Tensor):  # torch.ao's dynamically quantized Linear: its weight is a method
        return layer(x)
    large_fp32 = w.numel() >= ONEDNN_MIN_WEIGHT and x.dtype == w.dtype == torch.float32 and not x.is_cuda
    if _ONEDNN and large_fp32 and not torch.compiler.is_compiling():
        return torch.ops.mkldnn._linear_pointwise(x, w, layer.bias, "none", [], "")
    return F.linear(x, w, layer.bias)


@full_precision  # the SSD's decays and products in fp32 under autocast, as in Mamba2Mixer.mix
def short_mix(mixer, zxbcdt: torch.Tensor) -> torch.Tensor:
    """``mixer.mix(zxbcdt)`` (a :class:`~skeleton_mamba.mixer.Mamba2Mixer`) from a zero state, inference only.

    Args:
        mixer (Mamba2Mixer): the mixer whose weights are used.
        zxbcdt: (b, L, F) its ``in_proj`` output.

    Returns:
        (b, L, d_inner) the gated SSM output (with the gated-MLP channels in front when d_ssm < d_inner),
        what :meth:`Mamba2Mixer.mix` returns, to the rounding of the compute dtype.
    """
    b, L, _ = zxbcdt.shape
    H, P, G, N = mixer.nheads, mixer.headdim, mixer.ngroups, mixer.d_state
    z0, x0, z, xbc, dt = mixer.split(zxbcdt)
    ct = compute_dtype(xbc)
    xbc = F.silu(causal_conv_taps(xbc, mixer.conv1d.weight[:, 0], mixer.conv1d.bias)).to(ct)
    x, B, C = mixer.split_xbc(xbc)
    x = x.view(b, L, H, P)
    delta = discretize_dt(dt, mixer.dt_bias, True, mixer.dt_limit, ct)  # (b, L, H)
    # float64 cumulative log decays, per head: cs (b, H, L).
    A = -torch.exp(mixer.A_log.to(torch.float64))
    a = (delta.to(torch.float64) * A).transpose(1, 2)  # (b, H, L)
    if torch.compiler.is_compiling():  # a reduction inductor fuses (its cumsum is a library call)
        cs = (a[..., None, :] * torch.ones(L, L, dtype=a.dtype, device=a.device).tril_()).sum(-1)
    else:
        cs = a.cumsum(dim=-1)
    y = masked_quadratic(x * delta[..., None], cs, B.view(b, L, G, N), C.view(b, L, G, N))  # (b, L, H, P)
    y = mixer.skip(y, x)
    return mixer.output(y.reshape(b, L, mixer.d_ssm).to(zxbcdt.dtype), z, z0, x0)


class FrameOps:
    """The operations :meth:`SkeletonMambaBlock.spatial` takes for one frame (``ops=FrameOps``)."""

    linear = staticmethod(linear)
    mix = staticmethod(short_mix)


__all__ = ["FrameOps", "linear", "short_mix"]
