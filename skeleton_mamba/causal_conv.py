"""Causal depthwise convolution over time for CPUs, with a hand-written backward.

``y[b, t, c] = bias[c] + sum_s weight[c, s] * x[b, t - (k - 1) + s, c]`` (zero before t = 0): the
``conv1d`` of the Mamba-2 mixer (``groups = channels``, ``padding = k - 1``, first L outputs kept).
CPU builds of PyTorch run the depthwise ``convolution_backward`` slowly, and composing it from
``k`` shifted products makes 2k full-size temporaries forward and more backward. Here the forward
accumulates the k taps in place into one output, and the backward accumulates the input gradient
in place into one buffer; only the weight gradient takes one product per tap.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


class CausalDepthwiseConv(torch.autograd.Function):
    """x (B, L, C), weight (C, k), bias (C) or ``None`` -> (B, L, C)."""

    @staticmethod
    def forward(ctx, x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None) -> torch.Tensor:
        k, length = weight.shape[1], x.shape[1]
        taps = weight.t()  # (k, C): tap s multiplies input t - (k - 1) + s
        padded = F.pad(x, (0, 0, k - 1, 0))
        out = x * taps[k - 1] if bias is None else torch.addcmul(bias, x, taps[k - 1])
        for s in range(k - 1):
            out.addcmul_(padded[:, s : s + length], taps[s])
        ctx.save_for_backward(padded, taps)
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        padded, taps = ctx.saved_tensors
        k, length = taps.shape[0], grad.shape[1]
        grad = grad.contiguous()
        grad_x = grad_w = grad_b = None
        if ctx.needs_input_grad[0]:
            # Input t - (k - 1) + s feeds output t through tap s.
            grad_padded = grad.new_zeros(padded.shape)
            for s in range(k):
                grad_padded[:, s : s + length].addcmul_(grad, taps[s])
            grad_x = grad_padded[:, k - 1 :]
        if ctx.needs_input_grad[1]:
            grad_w = torch.stack(
                [(grad * padded[:, s : s + length]).sum(dim=(0, 1)) for s in range(k)], dim=1
            )
        if ctx.needs_input_grad[2]:
            grad_b = grad.sum(dim=(0, 1))
        return grad_x, grad_w, grad_b


def causal_depthwise_conv(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None) -> torch.Tensor:
    """Causal depthwise convolution along dim 1: x (B, L, C), weight (C, k), bias (C) or None -> (B, L, C)."""
    return CausalDepthwiseConv.apply(x, weight, bias)
