"""A benchmark script run on an earlier commit and on the working tree, alternately, in one run.

Speed claims compare "before" and "after" measured side by side: on a shared machine the load changes from
minute to minute, so two runs an hour apart say little. This builds the package of ``--before REV`` (a
commit, branch or tag of this repository: ``git archive``, then ``pip install --no-deps --target`` into
a temporary folder; nothing else in the environment changes), then runs the benchmark script -- always
the working tree's copy, so both sides measure the same thing -- ``--rounds`` times per side, before and
after in turn, each in a fresh process with ``--json``. It reports, for every number in the script's JSON
(nested objects under dotted names, ``paper.step.median_ms``), the median over the rounds of each side and
``before / after`` (above 1: the working tree is faster, for times). Each process states which package it
imported, and a round whose package is not the intended one stops the run.

    python benchmarks/side_by_side.py --before 99f3cf0 -- bench_demo_step.py --repeats 5
    python benchmarks/side_by_side.py --before HEAD~3 --rounds 7 --json -- bench_stream.py
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent

# Runs a script with the package found first in SITE (when given): the editable install's import hook,
# which would otherwise map skeleton_mamba to the working tree, is taken off sys.meta_path.
BOOTSTRAP = """
import runpy, sys
site, script, args = sys.argv[1], sys.argv[2], sys.argv[3:]
if site:
    sys.path.insert(0, site)
    sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in getattr(f, "__module__", "").lower()]
import skeleton_mamba
print("side_by_side package:", skeleton_mamba.__file__, file=sys.stderr)
sys.argv = [script, *args]
runpy.run_path(script, run_name="__main__")
"""


def build(rev: str, folder: Path) -> Path:
    """The package of commit ``rev`` installed (no dependencies) into ``folder/site``; returns that path."""
    source, site = folder / "source", folder / "site"
    source.mkdir()
    archive = subprocess.run(["git", "-C", str(REPO), "archive", rev], check=True, capture_output=True)
    subprocess.run(["tar", "-x", "-C", str(source)], input=archive.stdout, check=True)
    pip = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--target"]
    done = subprocess.run([*pip, str(site), str(source)], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"side_by_side: cannot build {rev}:\n{done.stderr[-2000:]}")
    return site


def run_once(site: Path | None, script: Path, args: list[str]) -> dict:
    """One process of the script with ``--json``; its JSON (the last line that starts an object)."""
    cmd = [sys.executable, "-c", BOOTSTRAP, str(site or ""), str(script), *args, "--json"]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
    if proc.returncode != 0:
        raise SystemExit(f"side_by_side: {script.name} failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    imported = next(
        (
            line.split(":", 1)[1].strip()
            for line in proc.stderr.splitlines()
            if line.startswith("side_by_side")
        ),
        "",
    )
    expected = str(site) if site else str(REPO)
    if not imported.startswith(expected):
        raise SystemExit(f"side_by_side: the run imported {imported!r}, not the package under {expected}")
    text = proc.stdout
    start = text.find("{")
    if start < 0:
        raise SystemExit(f"side_by_side: {script.name} printed no JSON:\n{text[-2000:]}")
    return json.loads(text[start:])


def numeric_fields(result: dict, prefix: str = "") -> dict[str, float]:
    """The numbers of a JSON object, nested objects included under dotted names (``paper.step.median_ms``)."""
    fields = {}
    for k, v in result.items():
        if isinstance(v, dict):
            fields.update(numeric_fields(v, f"{prefix}{k}."))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            fields[f"{prefix}{k}"] = float(v)
    return fields


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--" not in argv:
        raise SystemExit("usage: side_by_side.py --before REV [--rounds N] [--json] -- SCRIPT [ARGS...]")
    split = argv.index("--")
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--before", required=True, help="commit, branch or tag of the 'before' package")
    ap.add_argument("--rounds", type=int, default=5, help="processes per side, alternating")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv[:split])
    script, script_args = HERE / argv[split + 1], argv[split + 2 :]
    if not script.is_file():
        raise SystemExit(f"side_by_side: no benchmark script {script}")
    with tempfile.TemporaryDirectory(prefix="side_by_side_") as tmp:
        site = build(args.before, Path(tmp))
        runs: dict[str, list[dict]] = {"before": [], "after": []}
        for i in range(args.rounds):
            for side, where in (("before", site), ("after", None)):
                runs[side].append(run_once(where, script, script_args))
                print(f"round {i + 1}/{args.rounds} {side} done", file=sys.stderr, flush=True)
    keys = [k for k in numeric_fields(runs["after"][0]) if k in numeric_fields(runs["before"][0])]
    fields = {}
    for key in keys:
        before = statistics.median(numeric_fields(r)[key] for r in runs["before"])
        after = statistics.median(numeric_fields(r)[key] for r in runs["after"])
        fields[key] = {
            "before": before,
            "after": after,
            "before_over_after": round(before / after, 3) if after else None,
        }
    commit = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", args.before], capture_output=True, text=True
    )
    report = {
        "script": script.name,
        "args": script_args,
        "before": commit.stdout.strip() or args.before,
        "after": "working tree",
        "rounds": args.rounds,
        "machine": runs["after"][0].get("machine"),
        "fields": fields,
        "runs": runs,
    }
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        for key, f in fields.items():
            ratio = f["before_over_after"]
            print(f"{key:28s} before {f['before']:10.2f}  after {f['after']:10.2f}  before/after {ratio}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
