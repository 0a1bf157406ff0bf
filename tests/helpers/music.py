"""Music test signals."""

from __future__ import annotations

import numpy as np
import soundfile as sf


def click_track(path, bpm: float = 120.0, seconds: float = 8.0, sr: int = 22050) -> None:
    """A wav of short decaying 1 kHz clicks at ``bpm``."""
    y = np.zeros(int(seconds * sr), dtype=np.float32)
    n = np.arange(int(0.03 * sr))
    click = np.sin(2 * np.pi * 1000 * n / sr) * np.exp(-n / 100)
    for start in np.arange(0.5, seconds - 0.1, 60.0 / bpm):
        i = int(start * sr)
        y[i : i + click.size] += click.astype(np.float32)
    sf.write(path, y, sr)
