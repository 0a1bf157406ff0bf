"""A causal low-pass at a motion model's output: a cascade of exponential moving averages, trained through.

The live dancer regresses every pose frame on its own; what it has not learned is an error of its own at
each frame, driven by the frame-level music features (an onset spike moves the pose for one frame), so the
raw output trembles at 5-15 Hz although every training pose sequence is smooth. A causal filter at the
output, inside the network and trained through, removes what lies above the dance's band whatever the
network does, and the network learns to lead it (it sees the music up to the frame and its own state).

The filter is ``stages`` exponential moving averages in a row, each ``s_t = d s_{t-1} + (1 - d) x_t`` with
decay ``d`` (a gamma kernel: non-negative, no overshoot, unit gain at 0 Hz). Its power gain at frequency
``f`` (cycles per frame) is ``[(1 - d)^2 / (1 - 2 d cos(2 pi f) + d^2)]^stages``, its delay at low
frequencies ``stages d / (1 - d)`` frames. Every stage starts at the first frame's value (the filter at
rest on it), so a stream has no fade-in from zero::

    y = smoothing.sequence(x)                    # x (B, T, ...) -> y (B, T, ...), causal
    y_t, state = smoothing.step(x_t, state, started)   # the same, one frame at a time
    y = smoothing.continued(x, past)             # the same, its state given by its last K outputs

The cascade's transfer function ``(1 - d)^K / (1 - d z^-1)^K`` is also the recurrence over its own past
outputs ``y_t = (1 - d)^K x_t - sum_{j=1..K} C(K, j) (-d)^j y_{t-j}`` (:meth:`CausalSmoothing.continued`):
an autoregressive generator whose input window holds its last ``K`` output frames needs no other state, and
teacher forcing (the true past in that window) trains exactly the filter that generation runs ([QEAN]'s
dancer, ``QEANConfig.smoothing_stages``).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["CausalSmoothing"]

_TAIL = 1e-9  # the kernel is cut where the mass it leaves out falls below this


class CausalSmoothing(nn.Module):
    """``stages`` exponential moving averages of decay ``decay`` over time (0 stages: the identity).

    Args:
        stages: moving averages in a row (0 to 16).
        decay: each one's ``d`` in [0, 1) (0: the identity).
    """

    def __init__(self, stages: int = 0, decay: float = 0.6) -> None:
        super().__init__()
        if not 0 <= stages <= 16:
            raise ValueError(f"stages must be 0 to 16, got {stages}")
        if not 0.0 <= decay < 1.0:
            raise ValueError(f"decay must be in [0, 1), got {decay}")
        self.stages, self.decay = stages, decay
        self.register_buffer("kernel", self._kernel(), persistent=False)

    @property
    def enabled(self) -> bool:
        return self.stages > 0 and self.decay > 0

    def _kernel(self) -> torch.Tensor:
        """The impulse response h[n] = (1 - d)^K C(n + K - 1, K - 1) d^n, n = 0 .. L - 1, reversed for
        ``conv1d``; the mass beyond L (< 1e-9) is put on the last tap so the gain at 0 Hz is exactly 1."""
        if not self.enabled:
            return torch.ones(1, dtype=torch.float64)
        k, d = self.stages, self.decay
        taps, total, n = [], 0.0, 0
        while total < 1.0 - _TAIL:
            h = (1.0 - d) ** k * math.comb(n + k - 1, k - 1) * d**n
            taps.append(h)
            total += h
            n += 1
        taps[-1] += 1.0 - total
        return torch.tensor(taps[::-1], dtype=torch.float64)

    def power_gain(self, frequency: torch.Tensor) -> torch.Tensor:
        """The filter's power gain at ``frequency`` (cycles per frame, any shape)."""
        d = self.decay
        one = (1 - d) ** 2 / (1 - 2 * d * torch.cos(2 * math.pi * frequency) + d * d)
        return one**self.stages if self.enabled else torch.ones_like(frequency)

    def sequence(self, x: torch.Tensor) -> torch.Tensor:
        """x (B, T, ...) -> the filtered (B, T, ...), frame 0 held before the start."""
        if not self.enabled:
            return x
        b, t = x.shape[:2]
        flat = x.reshape(b, t, -1).transpose(1, 2).reshape(-1, 1, t)  # (B * C, 1, T)
        length = self.kernel.shape[0]
        padded = torch.cat([flat[..., :1].expand(-1, -1, length - 1), flat], dim=-1)
        y = F.conv1d(padded, self.kernel.to(x.dtype).view(1, 1, -1))  # (B * C, 1, T)
        return y.reshape(b, -1, t).transpose(1, 2).reshape(x.shape)

    def step(
        self, x: torch.Tensor, state: torch.Tensor | None, started: bool | torch.Tensor = True
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """One frame x (B, ...) and the stages' values (stages, B, ...) -> the filtered frame (B, ...) and the
        next state. ``started`` False (or 0; or ``state`` None) at a stream's first frame: the stages are
        then ignored and start at rest on x. A tensor ``started`` (0 or 1) keeps the step one graph."""
        if not self.enabled:
            return x, state
        rest = x.unsqueeze(0).expand(self.stages, *x.shape)
        if state is None or started is False:
            state = rest
        elif isinstance(started, torch.Tensor):
            state = started * state + (1 - started) * rest
        values, y = [], x
        for previous in state:
            y = self.decay * previous + (1.0 - self.decay) * y
            values.append(y)
        return y, torch.stack(values)

    def recurrence(self) -> tuple[float, list[float]]:
        """The input gain ``(1 - d)^K`` and the feedback coefficients ``c_j = -C(K, j) (-d)^j``, j = 1 .. K,
        of ``y_t = (1 - d)^K x_t + sum_j c_j y_{t-j}``."""
        k, d = self.stages, self.decay
        return (1.0 - d) ** k, [-math.comb(k, j) * (-d) ** j for j in range(1, k + 1)]

    def continued(self, x: torch.Tensor, past: torch.Tensor) -> torch.Tensor:
        """x (B, n, ...) the next inputs and past (B, >= K, ...) the filter's last K outputs -> its next n
        outputs (B, n, ...), the recurrence of the module docstring (the identity when disabled)."""
        if not self.enabled:
            return x
        if past.shape[1] < self.stages or past.shape[2:] != x.shape[2:]:
            raise ValueError(
                f"past must be (B, >= {self.stages}, {tuple(x.shape[2:])}), got {tuple(past.shape)}"
            )
        gain, feedback = self.recurrence()
        outputs = list(past[:, -self.stages :].unbind(1))
        for t in range(x.shape[1]):
            y = gain * x[:, t]
            for j, c in enumerate(feedback, start=1):
                y = y + c * outputs[-j]
            outputs.append(y)
        return torch.stack(outputs[self.stages :], dim=1)

    def extra_repr(self) -> str:
        return f"stages={self.stages}, decay={self.decay}"
