"""benchmarks/side_by_side.py: a benchmark on an earlier commit's package and on the working tree, in turn."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.helpers.repo import load_script

REPO = Path(__file__).resolve().parents[2]


def _load():
    return load_script("benchmarks/side_by_side.py")


def _git_checkout() -> bool:
    if shutil.which("git") is None:
        return False
    done = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True)
    return done.returncode == 0


@pytest.mark.slow  # builds the package of HEAD (about 20 s) and runs the demo step benchmark twice
@pytest.mark.skipif(not _git_checkout(), reason="needs a git checkout of the project (git archive HEAD)")
def test_runs_each_side_on_its_own_package(capsys):
    side_by_side = _load()
    args = ["--before", "HEAD", "--rounds", "1", "--json", "--", "bench_demo_step.py", "--repeats", "1"]
    assert side_by_side.main(args) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["script"] == "bench_demo_step.py" and report["rounds"] == 1
    step = report["fields"]["train_step_ms"]
    assert step["before"] > 0 and step["after"] > 0
    assert step["before_over_after"] == pytest.approx(step["before"] / step["after"], rel=1e-3)
    assert len(report["runs"]["before"]) == len(report["runs"]["after"]) == 1


def test_refuses_a_missing_script_and_reports_numeric_fields():
    side_by_side = _load()
    with pytest.raises(SystemExit, match="no benchmark script"):
        side_by_side.main(["--before", "HEAD", "--", "no_such_bench.py"])
    with pytest.raises(SystemExit, match="usage"):
        side_by_side.main(["--before", "HEAD"])
    fields = side_by_side.numeric_fields({"ms": 3, "rate": 1.5, "ok": True, "name": "x", "rows": [1]})
    assert fields == {"ms": 3.0, "rate": 1.5}
    report = {"paper": {"step": {"median_ms": 2, "ok": False}, "fps": 30}, "n": 1}
    nested = side_by_side.numeric_fields(report)
    assert nested == {"paper.step.median_ms": 2.0, "paper.fps": 30.0, "n": 1.0}
