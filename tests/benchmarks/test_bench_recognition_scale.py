"""benchmarks/README.md's recognition-at-scale table is generated from bench_recognition_scale.json, and that
recorded run shows what the memory-mapped store promises (issue 60, item 3)."""

from __future__ import annotations

import json
from pathlib import Path

from tests.helpers.repo import load_script

REPO = Path(__file__).resolve().parents[2]
bench = load_script("benchmarks/bench_recognition_scale.py")
MARK, END = "<!-- bench_recognition_scale -->", "<!-- /bench_recognition_scale -->"


def _report() -> dict:
    return json.loads((REPO / "benchmarks" / "bench_recognition_scale.json").read_text())


def test_the_readme_table_is_the_recorded_run():
    text = (REPO / "benchmarks" / "README.md").read_text(encoding="utf-8")
    block = text[text.index(MARK) + len(MARK) : text.index(END)].strip()
    assert block == bench.table(_report()), "run `python benchmarks/bench_recognition_scale.py --table`"


def test_the_recorded_run_meets_the_goals_at_full_size():
    """One copy per machine: a rank holds privately under a tenth of the data set, however many ranks; the
    loader workers do not grow over the epoch; setup under 30 s with the store built."""
    report = _report()
    assert report["scale"] == 1.0
    for name, entry in report["datasets"].items():
        size = entry["build"]["store_mb"]
        for world in (1, 2):
            ranks = entry[f"store_{world}"]
            assert len(ranks) == world
            for rank in ranks:
                assert rank["data_private_mb"] < 0.1 * size, (name, world, rank["data_private_mb"], size)
                assert rank["setup_s"] < 30, (name, world)
                pairs = zip(rank["workers_first_batch"], rank["workers_end"], strict=True)
                growth = [end["private_dirty"] - first["private_dirty"] for first, end in pairs]
                assert max(growth) < 0.02 * size, (name, world, growth)
        before = entry.get("pickle_2")
        if isinstance(before, list):  # the old way held a copy per rank (where it fitted in memory)
            assert min(r["data_private_mb"] for r in before) > 0.5 * size
        else:
            assert "skipped" in before
