"""The generative demos on several seeds: run them, keep what they printed, and generate the docs' tables.

``python benchmarks/demo_seeds.py run --demos egodance qean --seeds 0 1 2 3`` runs ``sm fit --recipe
<demo recipe> --seed_everything S`` for each demo and seed in a working folder of its own per demo (the
generated data are built once and reused), reads the ``demo.json`` the run wrote and the lines it printed,
and merges each seed's row into :data:`RESULTS` (``benchmarks/demo_seeds.json``): the dance's scores, every
``NOT reached`` line, the run's wall time and the machine.

``python benchmarks/demo_seeds.py record DEMO SEED DEMO_JSON LOG --wall-s S`` merges a run made by hand.

``python benchmarks/demo_seeds.py tables`` rewrites every table of the README and the tutorials that stands
between ``<!-- demo_seeds: NAME -->`` and ``<!-- /demo_seeds -->`` from that file (``--check``: only say
which differ, exit 1; ``tests/benchmarks/test_demo_tables.py`` runs it), so no figure of the demos is typed.

``python benchmarks/demo_seeds.py check-run DEMO_JSON LOG --demo egodance --seed 0`` is CI's guard of the main
job: it fails when the run differs from the published row of that seed: a score by more than the rounding of
the printed figure, or a ``NOT reached`` line the row does not list (so the docs' tables show every target the
main job misses; ``--strict`` fails on any ``NOT reached`` line). A run is the same number for number only on
the same float path: each row records the machine's (:func:`float_path`: the CPU's family, model and
instruction-set flags, the vector kernels PyTorch dispatches to, torch's and numpy's versions), and 400 steps
of training carry a last-bit difference of a kernel into every score. On another float path the scores are
compared within :data:`OTHER_PATH_RELATIVE` of the published figure (the targets, printed by the run, must
still all be reached), and the guard says so.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from datetime import date
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "demo_seeds.json"
DOCS = (
    "README.md",
    "docs/getting-started.md",
    "docs/how-to/long-songs.md",
    "docs/tutorials/egodance.md",
    "docs/tutorials/qean.md",
    "docs/tutorials/stream.md",
    "docs/tutorials/text2motion.md",
)
RECIPES = {
    "egodance": "egodance_demo.yaml",
    "qean": "qean_demo.yaml",
    "stream": "stream_dance_demo.yaml",
    "text2motion": "humanml3d_demo.yaml",
}
DYNAMICS = ("amplitude_ratio", "jitter_ratio", "high_frequency_ratio")
NOT_REACHED = re.compile(r"^\s*NOT reached: .*$", re.MULTILINE)
PRINTED_DECIMALS = 3  # every score the demos print has three decimals


def _dance(columns: dict, keys) -> dict:
    return {k: columns["dance"][k] for k in keys}


EGODANCE_WINDOWS = ("plausibility_m", "mpjpe_m", "beat_align", "beat_margin", "foot_skating", *DYNAMICS)


def _egodance(summary: dict) -> dict:
    scores = summary["scores"]
    row = {
        "windows": _dance(scores, EGODANCE_WINDOWS),
        "baselines": {c: scores[c] for c in ("ground_truth", "mean_pose", "random_clip")},
    }
    long = summary.get("long_form")
    if long:
        row["long_song"] = {
            "mpjpe_m": long["mpjpe_m"],
            "windows_alone_mpjpe_m": long["windows_alone_mpjpe_m"],
            "mean_pose_mpjpe_m": long["mean_pose_mpjpe_m"],
            **{f"seam_{k}": v for k, v in long["seams"].items()},
            **long["drift"],
            "head_source": long["head_source"],
        }
        if "heading" in long:
            row["long_song"]["heading"] = long["heading"]
    return row


def _dancer(summary: dict) -> dict:
    """The live dancer's and QEAN's common row: dynamics, the random clip, the beat margin when printed."""
    row = {
        "dance": _dance(summary["scores"], DYNAMICS),
        "baselines": {"random_clip": summary["scores"]["random_clip"]},
    }
    if "conditioning" in summary:  # the beat margin over chance on the held-out music, beside the truth's
        row["conditioning"] = {k: summary["conditioning"][k] for k in ("margin", "truth_margin")}
    return row


def _qean(summary: dict) -> dict:
    protocol = summary["protocol"]
    return {
        **_dancer(summary),
        "protocol": {k: protocol[k] for k in ("FID_k", "Dist_k", "BeatAlign") if k in protocol},
    }


def _text2motion(summary: dict) -> dict:
    scores = summary["scores"]
    columns = scores["dynamics"]["columns"]
    row = {
        "captions": {k: scores[k] for k in ("plausibility_m", "within_caption_m", "between_captions_m")},
        "dance": _dance(columns, DYNAMICS),
        "baselines": {"random_clip": columns["random_clip"]},
    }
    if "actions" in summary:  # the paraphrased prompts whose motion shows their action
        row["actions"] = {"shown": summary["actions"]["shown"]}
    return row


ROWS: dict[str, Callable[[dict], dict]] = {
    "egodance": _egodance,
    "qean": _qean,
    "stream": _dancer,
    "text2motion": _text2motion,
}


OTHER_PATH_RELATIVE = 0.5  # on another float path: within half the published figure (or 0.02 absolute)
OTHER_PATH_ABSOLUTE = 0.02


def float_path() -> str:
    """The machine's float path in one line: what makes two runs of the same code equal bit for bit."""
    import numpy
    import torch

    info: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                key, _, value = line.partition(":")
                info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    flags = hashlib.sha256(" ".join(sorted(info.get("flags", "").split())).encode()).hexdigest()[:8]
    cpu = f"{platform.machine()} family {info.get('cpu family', '?')} model {info.get('model', '?')}"
    capability = torch.backends.cpu.get_cpu_capability()
    return f"{cpu} flags {flags}; torch {torch.__version__} {capability}; numpy {numpy.__version__}"


def machine() -> str:
    """The machine the figures come from, in one line."""
    cpu = platform.machine()
    try:
        cpu = next(
            line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")
        )
    except (OSError, StopIteration):
        pass
    return f"{cpu}, {os.cpu_count()} logical cores, {platform.system()}"


def load_results(path: Path = RESULTS) -> dict:
    return json.loads(path.read_text(encoding="utf-8")) if path.exists() else {"demos": {}}


def write_results(results: dict, path: Path = RESULTS) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    tmp.replace(path)


def newest_demo_json(folder: Path) -> Path:
    found = sorted(folder.glob("runs/*/version_*/demo/demo.json"), key=lambda p: p.stat().st_mtime)
    if not found:
        raise FileNotFoundError(f"{folder}: the run wrote no runs/*/version_*/demo/demo.json")
    return found[-1]


def run_row(demo: str, demo_json: Path, log: Path, wall_s: float, command: str) -> dict:
    """The row of one finished run: its ``demo.json``, the ``NOT reached`` lines of its ``log``, its wall
    time."""
    summary = json.loads(demo_json.read_text(encoding="utf-8"))
    printed = log.read_text(encoding="utf-8", errors="replace")
    return {
        **ROWS[demo](summary),
        "not_reached": [line.strip() for line in NOT_REACHED.findall(printed)],
        "global_step": summary.get("global_step"),
        "wall_s": round(wall_s, 1),
        "machine": machine(),
        "float_path": float_path(),
        "date": date.today().isoformat(),
        "command": command,
    }


def run_demo(demo: str, seed: int, work: Path, extra: list[str]) -> dict:
    """Run one demo on one seed in ``work`` and return its row."""
    work.mkdir(parents=True, exist_ok=True)
    command = ["sm", "fit", "--recipe", RECIPES[demo], "--seed_everything", str(seed), *extra]
    log = work / f"seed{seed}.log"
    start = time.perf_counter()
    with open(log, "w", encoding="utf-8") as f:
        done = subprocess.run(command, cwd=work, stdout=f, stderr=subprocess.STDOUT, check=False)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited {done.returncode}; its output: {log}")
    return run_row(demo, newest_demo_json(work), log, wall, " ".join(command))


def merge_row(demo: str, seed: int, row: dict, path: Path = RESULTS) -> None:
    """Put ``row`` into the results file as ``demo``'s seed ``seed``."""
    results = load_results(path)  # re-read: another run may have merged rows meanwhile
    entry = results["demos"].setdefault(demo, {"recipe": RECIPES[demo], "seeds": {}})
    entry["seeds"][str(seed)] = row
    write_results(results, path)


# --- the tables -------------------------------------------------------------------------------------------


def _f(value, decimals: int = PRINTED_DECIMALS) -> str:
    return f"{value:.{decimals}f}"


def _span(values, decimals: int = 2) -> str:
    low, high = min(values), max(values)
    return (
        _f(low, decimals)
        if _f(low, decimals) == _f(high, decimals)
        else f"{_f(low, decimals)}-{_f(high, decimals)}"
    )


def _signed_span(values) -> str:
    """``+a`` or ``+a to +b``: a span of values that may be negative, three decimals."""
    low, high = (f"{f(values):+.3f}" for f in (min, max))
    return low if low == high else f"{low} to {high}"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def _seeds(results: dict, demo: str) -> list[tuple[str, dict]]:
    seeds = results["demos"].get(demo, {}).get("seeds", {})
    if not seeds:
        raise KeyError(
            f"no run of the {demo} demo recorded: python benchmarks/demo_seeds.py run --demos {demo}"
        )
    return sorted(seeds.items(), key=lambda kv: int(kv[0]))


def _first(results: dict, demo: str) -> dict:
    return _seeds(results, demo)[0][1]


def _reached(row: dict) -> str:
    return "all" if not row["not_reached"] else f"{len(row['not_reached'])} NOT reached"


def egodance_windows(results: dict) -> str:
    keys = EGODANCE_WINDOWS
    header = ["seed", "plausibility (m)", "MPJPE (m)", "BeatAlign", "over chance", "foot skating",
              "amplitude ratio", "jitter ratio", "energy above 6 Hz", "targets"]  # fmt: skip
    rows = [[s, *(_f(r["windows"][k]) for k in keys), _reached(r)] for s, r in _seeds(results, "egodance")]
    base = _first(results, "egodance")["baselines"]
    names = {
        "ground_truth": "ground truth",
        "mean_pose": "training mean pose",
        "random_clip": "random training clip",
    }
    rows += [[names[c], *(_f(base[c][k]) for k in keys), ""] for c in names]
    mean_pose, random_clip = base["mean_pose"], base["random_clip"]
    rows.append(["target", "<= 0.080", f"< {_f(min(mean_pose['mpjpe_m'], random_clip['mpjpe_m']))}",
                 f"> {_f(random_clip['beat_align'])}",
                 f">= {_f(base['ground_truth']['beat_margin'] / 2)}", "",
                 ">= 0.7", "<= 1.5", "0.5 to 2", ""])  # fmt: skip
    return _table(header, rows)


def egodance_long_song(results: dict) -> str:
    header = ["seed", "whole-song MPJPE (m)", "/ mean pose", "segments alone (m)", "mean pose (m)",
              "seam speed", "seam acceleration", "seam root step", "end heading error (deg)",
              "end root distance (m)"]  # fmt: skip
    rows = []
    for seed, row in _seeds(results, "egodance"):
        long = row["long_song"]
        rows.append([seed, _f(long["mpjpe_m"]), _f(long["mpjpe_m"] / long["mean_pose_mpjpe_m"], 2),
                     _f(long["windows_alone_mpjpe_m"]), _f(long["mean_pose_mpjpe_m"]),
                     _f(long["seam_speed_ratio"], 2), _f(long["seam_acceleration_ratio"], 2),
                     _f(long["seam_root_step_ratio"], 2), _f(long["end_heading_error_deg"], 0),
                     _f(long["end_root_distance_m"], 2)])  # fmt: skip
    rows.append(["target", "", "<= 0.85", "whole <= 1.1x alone", "", "<= 1.5", "<= 1.5", "<= 2", "<= 30", ""])
    return _table(header, rows)


def _dynamics_rows(results: dict, demo: str, extra: Callable[[dict], list[str]]) -> list[list[str]]:
    return [
        [s, *(_f(r["dance"][k]) for k in DYNAMICS), *extra(r), _reached(r)] for s, r in _seeds(results, demo)
    ]


def _margin(r: dict) -> list[str]:
    """The beat margin over chance column: the dance's, the truth's in brackets."""
    c = r.get("conditioning")
    return [f"{c['margin']:+.3f} ({c['truth_margin']:+.3f})" if c else ""]


def qean_seeds(results: dict) -> str:
    header = ["seed", "amplitude ratio", "jitter ratio", "energy above 6 Hz", "FID_k", "Dist_k", "BeatAlign",
              "beat margin over chance (truth)", "targets"]  # fmt: skip

    def protocol(r: dict) -> list[str]:
        p = r["protocol"]
        return [_f(p["FID_k"], 1), _f(p["Dist_k"], 2), _f(p["BeatAlign"]), *_margin(r)]

    rows = _dynamics_rows(results, "qean", protocol)
    clip = _first(results, "qean")["baselines"]["random_clip"]
    rows.append(["random training clip", *(_f(clip[k]) for k in DYNAMICS), "", "", "", "", ""])
    rows.append(["target", ">= 0.7", "<= 1.5", "0.5 to 2", "", "", "", ">= half the truth's", ""])
    return _table(header, rows)


def stream_seeds(results: dict) -> str:
    header = ["seed", "amplitude ratio", "jitter ratio", "energy above 6 Hz",
              "beat margin over chance (truth)", "targets"]  # fmt: skip

    rows = _dynamics_rows(results, "stream", _margin)
    clip = _first(results, "stream")["baselines"]["random_clip"]
    rows.append(["random training clip", *(_f(clip[k]) for k in DYNAMICS), "", ""])
    rows.append(["target", ">= 0.7", "<= 1.5", "0.5 to 2", ">= half the truth's", ""])
    return _table(header, rows)


def text2motion_seeds(results: dict) -> str:
    keys = ("plausibility_m", "within_caption_m", "between_captions_m")
    seeds = _seeds(results, "text2motion")
    acted = any("actions" in r for _, r in seeds)  # the column of the action check, once a run has it
    header = ["seed", "plausibility (m)", "within a caption (m)", "between captions (m)",
              *(["action shown"] if acted else []), "amplitude ratio", "jitter ratio", "energy above 6 Hz",
              "targets"]  # fmt: skip

    def shown(r: dict) -> list[str]:
        return [f"{r['actions']['shown']:.0%}" if "actions" in r else ""] if acted else []

    rows = [[s, *(_f(r["captions"][k]) for k in keys), *shown(r), *(_f(r["dance"][k]) for k in DYNAMICS),
             _reached(r)] for s, r in seeds]  # fmt: skip
    clip = _first(results, "text2motion")["baselines"]["random_clip"]
    blank = [""] * (4 if acted else 3)
    rows.append(["random training clip", *blank, *(_f(clip[k]) for k in DYNAMICS), ""])
    rows.append(["target", "<= 0.080", "", "> within", *([">= 80%"] if acted else []), ">= 0.7", "<= 1.5",
                 "0.5 to 2", ""])  # fmt: skip
    return _table(header, rows)


def readme_demos(results: dict) -> str:
    header = ["demo", "seeds", "amplitude ratio", "jitter ratio", "energy above 6 Hz", "own scores",
              "targets reached"]  # fmt: skip

    def spans(rows: list[dict], get: Callable[[dict], dict]) -> list[str]:
        return [_span([get(r)[k] for r in rows]) for k in DYNAMICS]

    def reached(rows: list[dict]) -> str:
        missed = sum(bool(r["not_reached"]) for r in rows)
        return "every seed" if not missed else f"{len(rows) - missed} of {len(rows)} seeds"

    out = []
    ego = [r for _, r in _seeds(results, "egodance")]
    if ego:  # every demo has rows (_seeds raises otherwise)
        own = (f"MPJPE {_span([r['windows']['mpjpe_m'] for r in ego], 3)} m; 60 s song "
               f"{_span([r['long_song']['mpjpe_m'] for r in ego], 3)} m (mean pose "
               f"{_f(ego[0]['long_song']['mean_pose_mpjpe_m'])}), heading off "
               f"{_span([r['long_song']['end_heading_error_deg'] for r in ego], 0)} deg "
               "at its end")  # fmt: skip
        seeds = _seed_list(results, "egodance")
        out.append(["`egodance_demo.yaml`", seeds, *spans(ego, lambda r: r["windows"]),
                    own, reached(ego)])  # fmt: skip
    t2m = [r for _, r in _seeds(results, "text2motion")]
    if t2m:
        own = f"plausibility {_span([r['captions']['plausibility_m'] for r in t2m], 3)} m"
        if all("actions" in r for r in t2m):
            low, high = (f(r["actions"]["shown"] for r in t2m) for f in (min, max))
            span = f"{low:.0%}" + (f"-{high:.0%}" if high > low else "")
            own += f"; paraphrased prompts showing their action {span}"
        seeds = _seed_list(results, "text2motion")
        out.append(["`humanml3d_demo.yaml`", seeds, *spans(t2m, lambda r: r["dance"]),
                    own, reached(t2m)])  # fmt: skip

    def margins(rows: list[dict]) -> str:  # the dancers' beat margin over chance, when every seed has it
        if not all("conditioning" in r for r in rows):
            return ""
        dance, truth = ([r["conditioning"][k] for r in rows] for k in ("margin", "truth_margin"))
        return f"beat margin {_signed_span(dance)} (truth {_signed_span(truth)})"

    stream = [r for _, r in _seeds(results, "stream")]
    if stream:
        out.append(["`stream_dance_demo.yaml`", _seed_list(results, "stream"),
                    *spans(stream, lambda r: r["dance"]), margins(stream), reached(stream)])  # fmt: skip
    qean = [r for _, r in _seeds(results, "qean")]
    if qean:
        own = f"BeatAlign {_span([r['protocol']['BeatAlign'] for r in qean])} (FACT)"
        own += f"; {margins(qean)}" if margins(qean) else ""
        out.append(["`qean_demo.yaml`", _seed_list(results, "qean"), *spans(qean, lambda r: r["dance"]), own,
                    reached(qean)])  # fmt: skip
    own = "beat margin over chance >= half the truth's" if margins(stream + qean) else ""
    out.append(["target", "", ">= 0.7", "<= 1.5", "0.5 to 2", own, ""])
    return _table(header, out)


def _seed_list(results: dict, demo: str) -> str:
    seeds = [int(s) for s, _ in _seeds(results, demo)]
    return (
        f"{seeds[0]}-{seeds[-1]}"
        if seeds == list(range(seeds[0], seeds[-1] + 1))
        else ", ".join(map(str, seeds))
    )


def runs_line(results: dict, demo: str) -> str:
    """Where and how long the runs of ``demo`` took."""
    rows = [r for _, r in _seeds(results, demo)]
    walls = [r["wall_s"] / 60 for r in rows]
    return (f"Runs of {_seed_list(results, demo)} on {rows[0]['machine']}, {rows[0]['date']}: "
            f"{_span(walls, 1)} minutes each, beside other jobs "
            f"(`python benchmarks/demo_seeds.py run --demos {demo}`).")  # fmt: skip


CAUSE = REPO / "benchmarks" / "long_song_cause.json"


def egodance_cause(results: dict) -> str:
    """The long song's error by held-out window and segment, and the head estimator's yaw, for a run
    before the head's turns were a condition and one after (``benchmarks/long_song_cause.py``'s JSON;
    ``results`` is not used)."""
    cause = json.loads(CAUSE.read_text(encoding="utf-8"))
    before, after = cause["before"], cause["after"]
    after_windows = {w["window"]: w for w in after["held_out_windows"]}
    rows = [[f"`{w['window'].removeprefix('synthetic_')}`", w["window"].split("_")[1], _f(w["mpjpe_m"]),
             _f(after_windows[w["window"]]["mpjpe_m"]), _f(w["mean_pose_mpjpe_m"])]
            for w in before["held_out_windows"]]  # fmt: skip
    table = _table(["held-out window", "style", "MPJPE before (m)", "MPJPE after (m)", "mean pose (m)"], rows)
    long, yaw = before["long_song"], before["head_estimator_yaw"]
    segments = ", ".join(_f(v) for v in long["per_segment_mpjpe_m"][:4])
    means = ", ".join(_f(v) for v in long["per_segment_mean_pose_mpjpe_m"][:4])
    error = yaw["error_at_next_window_deg"]

    def song(entry: dict) -> str:
        s = entry["long_song"]
        return (
            f"its windows sampled alone {_f(s['windows_alone_mpjpe_m'])} m (those starting every 5 s "
            f"{_f(s['even_windows_alone_mpjpe_m'])} m, half a window later "
            f"{_f(s['odd_windows_alone_mpjpe_m'])} m), joined with the overlaps in-painted "
            f"{_f(s['inpainted_mpjpe_m'])} m, cross-faded only {_f(s['cross_faded_mpjpe_m'])} m"
        )

    return (
        f"{table}\n\nThe long song's {len(long['per_segment_mpjpe_m'])} windows, the mean pose "
        f"{_f(long['mean_pose_mpjpe_m'])} m: before, {song(before)}; window by window {segments}, ... "
        f"against the mean pose's {means}, ...; after, {song(after)}. The head estimator's yaw (before) "
        "swings "
        f"{_f(yaw['estimated_swing_std_deg'], 1)} degrees (standard deviation after removing the slow turn) "
        f"where the truth's swings {_f(yaw['true_swing_std_deg'], 1)} (correlation "
        f"{_f(yaw['swing_correlation'], 2)}), and is {_f(error['min'], 0)} to {_f(error['max'], 0)} degrees "
        "off (mean "
        f"{_f(error['mean'], 0)}) at the next window's first frame. Measured by "
        "`python benchmarks/long_song_cause.py --as before|after` on seed 0's runs of the recipe without and "
        "with the head's turns as a condition."
    )


def egodance_heading_before(results: dict) -> str:
    """The end-of-song heading error before the video held the heading (the recorded row)."""
    (row,) = results["demos"]["egodance"]["before"].values()
    return f"{_f(row['long_song']['end_heading_error_deg'], 0)} degrees"


TABLES: dict[str, Callable[[dict], str]] = {
    "egodance-heading-before": egodance_heading_before,
    "egodance-cause": egodance_cause,
    "readme": readme_demos,
    "egodance-windows": egodance_windows,
    "egodance-long-song": egodance_long_song,
    "egodance-runs": lambda r: runs_line(r, "egodance"),
    "qean": qean_seeds,
    "qean-runs": lambda r: runs_line(r, "qean"),
    "stream": stream_seeds,
    "stream-runs": lambda r: runs_line(r, "stream"),
    "text2motion": text2motion_seeds,
    "text2motion-runs": lambda r: runs_line(r, "text2motion"),
}
BLOCK = re.compile(
    r"(<!-- demo_seeds: (?P<name>[\w-]+) -->\n?)(?P<body>.*?)(<!-- /demo_seeds -->)", re.DOTALL
)


def render_docs(text: str, results: dict) -> str:
    """``text`` with every ``demo_seeds`` block regenerated from ``results``."""

    def replace(match: re.Match) -> str:
        name = match["name"]
        if name not in TABLES:
            raise KeyError(f"unknown demo_seeds table {name!r} (known: {', '.join(TABLES)})")
        inline = not match[1].endswith("\n")  # a figure inside a sentence, not a table of its own
        return match[1] + TABLES[name](results) + ("" if inline else "\n") + match[4]

    return BLOCK.sub(replace, text)


def tables(check: bool, results_path: Path = RESULTS) -> list[str]:
    """Regenerate the docs' tables (``check``: write nothing); the files that differed."""
    results = load_results(results_path)
    stale = []
    for name in DOCS:
        path = REPO / name
        text = path.read_text(encoding="utf-8")
        new = render_docs(text, results)
        if new != text:
            stale.append(name)
            if not check:
                path.write_text(new, encoding="utf-8")
    return stale


# --- CI's guard of the main job ---------------------------------------------------------------------------


def _flatten(value, prefix: str = "") -> dict[str, float]:
    if isinstance(value, dict):
        out: dict[str, float] = {}
        for k, v in value.items():
            out.update(_flatten(v, f"{prefix}{k}."))
        return out
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return {prefix[:-1]: float(value)}
    return {}


def published_row(demo: str, seed: int, results_path: Path = RESULTS) -> dict | None:
    return load_results(results_path)["demos"].get(demo, {}).get("seeds", {}).get(str(seed))


def check_run(
    demo_json: Path, log: Path, demo: str, seed: int, results_path: Path = RESULTS, strict: bool = False,
    path: str | None = None,
) -> list[str]:  # fmt: skip
    """The problems of a run against the published row (empty: none): a ``NOT reached`` line the published
    row does not list (``strict``: any ``NOT reached`` line), a listed one the run reached (the row is
    stale), a score that differs by more than the rounding of the printed figure, or on another float path
    (``path``, default this machine's :func:`float_path`) by more than :data:`OTHER_PATH_RELATIVE`."""
    printed = [
        line.strip() for line in NOT_REACHED.findall(log.read_text(encoding="utf-8", errors="replace"))
    ]
    published = published_row(demo, seed, results_path)
    if published is None:
        return [*printed, f"{results_path.name} has no published row for {demo} seed {seed}"]
    known = [] if strict else published.get("not_reached", [])
    problems = [line for line in printed if line not in known]
    problems += [f"published as {line!r}, but the run reached it" for line in known if line not in printed]
    run = ROWS[demo](json.loads(demo_json.read_text(encoding="utf-8")))
    same_path = published.get("float_path") == (float_path() if path is None else path)
    mine = _flatten(run)
    for key, value in _flatten({k: v for k, v in published.items() if k in run}).items():
        tolerance = 0.5 * 10**-PRINTED_DECIMALS + 1e-9
        if not same_path:
            tolerance = max(tolerance, OTHER_PATH_ABSOLUTE, OTHER_PATH_RELATIVE * abs(value))
        if key not in mine:
            problems.append(f"{key}: published {value:.4f}, the run has none")
        elif abs(mine[key] - value) > tolerance:
            problems.append(f"{key}: the run {mine[key]:.4f}, published {value:.4f}")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run demos on seeds and merge their rows into the results")
    run.add_argument("--demos", nargs="+", choices=sorted(RECIPES), default=sorted(RECIPES))
    run.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3])
    run.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "sm-demo-seeds")
    run.add_argument("--results", type=Path, default=RESULTS)
    run.add_argument("--json", action="store_true", help="print the new rows as one JSON object")
    table = sub.add_parser("tables", help="regenerate the docs' tables from the results")
    table.add_argument("--check", action="store_true", help="write nothing; exit 1 when a table is stale")
    table.add_argument("--results", type=Path, default=RESULTS)
    record = sub.add_parser("record", help="merge the row of a run made by hand (its demo.json and log)")
    record.add_argument("demo", choices=sorted(RECIPES))
    record.add_argument("seed", type=int)
    record.add_argument("demo_json", type=Path)
    record.add_argument("log", type=Path)
    record.add_argument("--wall-s", type=float, required=True, help="the run's wall time in seconds")
    record.add_argument("--results", type=Path, default=RESULTS)
    guard = sub.add_parser("check-run", help="CI: a run's demo.json and log against the published row")
    guard.add_argument("demo_json", type=Path)
    guard.add_argument("log", type=Path)
    guard.add_argument("--demo", choices=sorted(RECIPES), default="egodance")
    guard.add_argument("--seed", type=int, default=0)
    guard.add_argument("--results", type=Path, default=RESULTS)
    guard.add_argument("--strict", action="store_true", help="fail on any NOT reached line, published or not")
    args, extra = parser.parse_known_args(argv)
    if args.command == "run":
        new = {}
        for demo in args.demos:
            for seed in args.seeds:
                row = run_demo(demo, seed, args.work / demo, extra)
                merge_row(demo, seed, row, args.results)
                new.setdefault(demo, {})[str(seed)] = row
                print(f"[demo_seeds] {demo} seed {seed}: {len(row['not_reached'])} NOT reached, "
                      f"{row['wall_s'] / 60:.1f} min", file=sys.stderr, flush=True)  # fmt: skip
        if args.json:
            print(json.dumps(new, indent=2))
        return 0
    if args.command == "record":
        command = f"sm fit --recipe {RECIPES[args.demo]} --seed_everything {args.seed}"
        merge_row(args.demo, args.seed, run_row(args.demo, args.demo_json, args.log, args.wall_s, command),
                  args.results)  # fmt: skip
        return 0
    if args.command == "tables":
        stale = tables(args.check, args.results)
        for name in stale:
            print(f"{name}: {'stale' if args.check else 'regenerated'} demo tables", file=sys.stderr)
        return 1 if args.check and stale else 0
    here = float_path()
    problems = check_run(args.demo_json, args.log, args.demo, args.seed, args.results, args.strict, here)
    published = published_row(args.demo, args.seed, args.results) or {}
    if published.get("float_path") != here:
        print(f"CI: the published row comes from another float path ({published.get('float_path')}; this "
              f"machine: {here}): scores compared within {OTHER_PATH_RELATIVE:.0%} or {OTHER_PATH_ABSOLUTE}, "
              "targets exactly")  # fmt: skip
    for line in problems:
        print(f"CI: main job: {line}", file=sys.stderr)
    if not problems:
        print(
            f"CI: the main job printed the published {args.demo} seed {args.seed} row "
            "(benchmarks/demo_seeds.json)"
        )
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
