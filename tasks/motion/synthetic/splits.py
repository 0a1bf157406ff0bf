"""Held-out dances of a generated demo set, stratified by style. SYNTHETIC data.

A hash split of a handful of dances can hold out only one style, or the one dance of a style, so the
test would ask for a style the model has barely seen (with 9 dances, seed 0: both test dances were
"bounce" and only one "bounce" dance was left to train on). Here every style keeps its slowest and its
fastest dance in training, and the held-out candidates of a style are its other dances, middle tempo
first, so a held-out dance is an unseen dance *within* the tempo range its style was trained on.
Candidates are taken one style at a time (styles ordered by a stable hash of their name): the first
``test`` to test, the next ``val`` to val, the rest train.
"""

from __future__ import annotations

import re
import zlib
from collections.abc import Sequence
from pathlib import Path

__all__ = ["DEMO_NAME", "parse_demo_name", "stratified_holdout"]

DEMO_NAME = re.compile(r"synthetic_(?P<style>[a-z]+)_(?P<bpm>[0-9.]+)bpm_s(?P<seed>[0-9]+)$")


def parse_demo_name(source: str) -> tuple[str, float, int]:
    """``.../synthetic_<style>_<bpm>bpm_s<seed>.npz`` -> (style, bpm, seed).

    Raises:
        ValueError: the name is not one :func:`~.write_dance` writes.
    """
    match = DEMO_NAME.match(Path(source).stem)
    if match is None:
        raise ValueError(
            f"{source}: not a generated demo dance (expected synthetic_<style>_<bpm>bpm_s<seed>)"
        )
    return match["style"], float(match["bpm"]), int(match["seed"])


def _stable(text: str) -> int:
    return zlib.crc32(text.encode())


def stratified_holdout(sources: Sequence[str], val: int, test: int) -> dict[str, str]:
    """Source -> ``train`` | ``val`` | ``test`` for generated dances (module docstring).

    Raises:
        ValueError: a name is not a generated dance, or the styles have fewer than ``val + test``
            dances beyond their slowest and fastest.
    """
    by_style: dict[str, list[tuple[float, str]]] = {}
    for src in sorted(set(sources)):
        style, bpm, _ = parse_demo_name(src)
        by_style.setdefault(style, []).append((bpm, src))
    queues = []
    for style in sorted(by_style, key=lambda s: (_stable(s), s)):
        dances = sorted(by_style[style])  # by tempo
        middle = (len(dances) - 1) / 2
        inner = list(enumerate(dances))[1:-1]  # the slowest and fastest stay in training
        queues.append([src for _, (_, src) in sorted(inner, key=lambda d: (abs(d[0] - middle), d[1]))])
    candidates = [q[r] for r in range(max(map(len, queues), default=0)) for q in queues if r < len(q)]
    if len(candidates) < val + test:
        raise ValueError(
            f"{len(sources)} dances in {len(by_style)} styles leave {len(candidates)} to hold out "
            f"(each style keeps its slowest and fastest), fewer than {test} test + {val} val: generate more"
        )
    out = dict.fromkeys(sources, "train")
    for i, src in enumerate(candidates[: test + val]):
        out[src] = "test" if i < test else "val"
    return out
