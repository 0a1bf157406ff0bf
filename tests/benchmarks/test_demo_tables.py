"""The demos' tables in the README and the tutorials are generated from benchmarks/demo_seeds.json.

``python benchmarks/demo_seeds.py run`` records what each demo printed on each seed; ``tables`` writes the
docs' tables from that file. These tests fail when a table was typed or left stale, and check the generator
and CI's guard of the main job on rows they build.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.helpers.repo import load_script

PATH = "x86_64 family 25 model 17 flags 0123abcd; torch 2.13.0 AVX512; numpy 2.3.0"  # a row's float path

REPO = Path(__file__).resolve().parents[2]


demo_seeds = load_script("benchmarks/demo_seeds.py")


def test_every_docs_table_equals_the_recorded_runs():
    results = demo_seeds.load_results()
    for name in demo_seeds.DOCS:
        text = (REPO / name).read_text(encoding="utf-8")
        assert demo_seeds.render_docs(text, results) == text, (
            f"{name}: a demo table differs from benchmarks/demo_seeds.json; "
            "run `python benchmarks/demo_seeds.py tables`"
        )


def test_every_demo_has_seeds_0_to_3_recorded():
    results = demo_seeds.load_results()
    for demo in demo_seeds.RECIPES:
        seeds = results["demos"][demo]["seeds"]
        assert {"0", "1", "2", "3"} <= set(seeds), f"{demo}: seeds {sorted(seeds)}"
        for seed, row in seeds.items():
            assert row["command"].endswith(f"--seed_everything {seed}"), row["command"]


def test_docs_hold_every_table_and_no_unknown_one():
    names = set()
    for name in demo_seeds.DOCS:
        names |= {m["name"] for m in demo_seeds.BLOCK.finditer((REPO / name).read_text(encoding="utf-8"))}
    assert names == set(demo_seeds.TABLES)


def _stream_row(amplitude: float, not_reached: list[str]) -> dict:
    dance = {"amplitude_ratio": amplitude, "jitter_ratio": 0.5, "high_frequency_ratio": 1.0}
    clip = {"amplitude_ratio": 1.0, "jitter_ratio": 1.3, "high_frequency_ratio": 10.0}
    return {"dance": dance, "baselines": {"random_clip": clip}, "not_reached": not_reached, "wall_s": 60.0,
            "machine": "m", "date": "2026-12-07", "command": "c"}  # fmt: skip


def test_tables_are_rendered_from_the_rows_in_a_block():
    results = {
        "demos": {
            "stream": {"seeds": {"0": _stream_row(0.9, []), "1": _stream_row(0.61, ["NOT reached: x"])}}
        }
    }
    results["demos"]["stream"]["seeds"]["0"]["conditioning"] = {"margin": 0.4, "truth_margin": 0.7}
    text = "before\n<!-- demo_seeds: stream -->\nold typed table\n<!-- /demo_seeds -->\nafter\n"
    out = demo_seeds.render_docs(text, results)
    assert "old typed table" not in out and out.startswith("before\n") and out.endswith("after\n")
    rows = [line for line in out.splitlines() if line.startswith("| ")]
    assert rows[1] == "| 0 | 0.900 | 0.500 | 1.000 | +0.400 (+0.700) | all |"
    assert rows[2] == "| 1 | 0.610 | 0.500 | 1.000 |  | 1 NOT reached |"  # a row from before the margin
    assert rows[3].startswith("| random training clip | 1.000 | 1.300 | 10.000")
    with pytest.raises(KeyError, match="no run of the qean demo"):
        demo_seeds.render_docs("<!-- demo_seeds: qean -->\n<!-- /demo_seeds -->", results)


def _egodance_summary(mpjpe: float) -> dict:
    column = {k: 0.5 for k in ("plausibility_m", "mpjpe_m", "beat_align", "beat_margin", "foot_skating",
                               "penetration_m",
                               "amplitude_ratio", "jitter_ratio", "high_frequency_ratio")}  # fmt: skip
    scores = {c: dict(column) for c in ("dance", "ground_truth", "mean_pose", "random_clip")}
    scores["dance"]["mpjpe_m"] = mpjpe
    return {"scores": scores, "long_form": None}


def test_check_run_fails_on_not_reached_and_on_a_row_that_moved(tmp_path):
    results = tmp_path / "results.json"
    published = demo_seeds.ROWS["egodance"](_egodance_summary(0.0764))
    results.write_text(
        json.dumps(
            {"demos": {"egodance": {"seeds": {"0": {**published, "not_reached": [], "float_path": PATH}}}}}
        )
    )
    log = tmp_path / "log"
    log.write_text("reached: a\n")
    run = tmp_path / "demo.json"
    for mpjpe, ok in (
        (0.0764, True),
        (0.0768, True),
        (0.0770, False),
        (0.0758, False),
    ):  # printed 0.076 / 0.077
        run.write_text(json.dumps(_egodance_summary(mpjpe)))
        problems = demo_seeds.check_run(run, log, "egodance", 0, results, path=PATH)
        assert (problems == []) is ok, (mpjpe, problems)
        # another float path (another CPU, other kernels): within half the figure
        assert demo_seeds.check_run(run, log, "egodance", 0, results, path="other") == []
    for mpjpe, ok in ((0.11, True), (0.12, False), (0.037, False)):
        run.write_text(json.dumps(_egodance_summary(mpjpe)))
        assert (demo_seeds.check_run(run, log, "egodance", 0, results, path="other") == []) is ok, mpjpe
    run.write_text(json.dumps(_egodance_summary(0.0764)))
    missed = "NOT reached: whole-sequence MPJPE below the mean-pose baseline"
    log.write_text(f"reached: a\n{missed}\n")
    assert demo_seeds.check_run(run, log, "egodance", 0, results) == [missed]  # not in the published row
    assert "no published row" in demo_seeds.check_run(run, log, "egodance", 1, results)[-1]
    # a row that lists the miss: the run must print it (strict: fails anyway)
    results.write_text(
        json.dumps({"demos": {"egodance": {"seeds": {"0": {**published, "not_reached": [missed]}}}}})
    )
    assert demo_seeds.check_run(run, log, "egodance", 0, results) == []
    assert demo_seeds.check_run(run, log, "egodance", 0, results, strict=True) == [missed]
    log.write_text("reached: a\n")
    assert demo_seeds.check_run(run, log, "egodance", 0, results) == [
        f"published as {missed!r}, but the run reached it"
    ]
