"""Causal depthwise convolution over time for CPUs, with a hand-written backward.

``y[b, t, c] = bias[c] + sum_s weight[c, s] * x[b, t - (k - 1) + s, c]`` (zero before t = 0): the
``conv1d`` of the Mamba-2 mixer (``groups = channels``, ``padding = k - 1``, first L outputs kept).
CPU builds of PyTorch run the depthwise ``convolution_backward`` slowly, and composing it from
``k`` shifted products makes 2k full-size temporaries forward and more backward. Here the forward
accumulates the k taps in place into one output (each tap into the shifted part of the output it
reaches, so the input is neither padded nor copied), and the backward accumulates the input
gradient in place into one buffer; only the weight gradient takes one product per tap.
"""

from __future__ import annotations

import torch


def causal_conv_taps(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None) -> torch.Tensor:
    """The forward alone (no autograd): x (B, L, C), weight (C, k), bias (C) or ``None`` -> (B, L, C)."""
    k, length = weight.shape[1], x.shape[1]
    taps = weight.t()  # (k, C): tap s multiplies input t - (k - 1) + s
    out = x * taps[k - 1] if bias is None else torch.addcmul(bias, x, taps[k - 1])
    for s in range(k - 1):
        shift = k - 1 - s
        if shift < length:
            out[:, shift:].addcmul_(x[:, : length - shift], taps[s])
    return out


class CausalDepthwiseConv(torch.autograd.Function):
    """x (B, L, C), weight (C, k), bias (C) or ``None`` -> (B, L, C).

    Tap s multiplies the input ``k - 1 - s`` steps back: it is added to the output from that position
    on (``out[:, shift:] += x[:, :L - shift] * w_s``), so nothing is padded or copied, and the
    backward reads the saved input itself.
    """

    @staticmethod
    def forward(ctx, x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None) -> torch.Tensor:
        ctx.save_for_backward(x, weight.t())
        return causal_conv_taps(x, weight, bias)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        x, taps = ctx.saved_tensors
        k, length = taps.shape[0], grad.shape[1]
        grad = grad.contiguous()
        grad_x = grad_w = grad_b = None
        shifts = [(s, k - 1 - s) for s in range(k) if k - 1 - s < length]
        if ctx.needs_input_grad[0]:
            # Input t feeds output t + shift through tap s.
            grad_x = grad * taps[k - 1]
            for s, shift in shifts[:-1]:
                grad_x[:, : length - shift].addcmul_(grad[:, shift:], taps[s])
        if ctx.needs_input_grad[1]:
            grad_w = x.new_zeros(taps.shape)  # (k, C)
            for s, shift in shifts:
                grad_w[s] = (grad[:, shift:] * x[:, : length - shift]).sum(dim=(0, 1))
            grad_w = grad_w.t()
        if ctx.needs_input_grad[2]:
            grad_b = grad.sum(dim=(0, 1))
        return grad_x, grad_w, grad_b


def causal_depthwise_conv(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None) -> torch.Tensor:
    """Causal depthwise convolution along dim 1: x (B, L, C), weight (C, k), bias (C) or None -> (B, L, C)."""
    return CausalDepthwiseConv.apply(x, weight, bias)
