"""The T2M results table: mean and 95 % interval per metric and row, printed and written as JSON / CSV.

Rows and columns as MDM's ``eval_humanml.py`` log and the published tables (R-Precision top-1/2/3,
FID, MM-Dist, Diversity, MultiModality); intervals ``1.96 std / sqrt(n)`` with the population std
(:func:`~.metrics.confidence_interval`, MDM ``get_metric_statistics``).
"""

from __future__ import annotations

import csv
import json
from os import PathLike
from pathlib import Path

import torch

from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.tasks.text2motion.metrics import confidence_interval

__all__ = ["METRICS", "COMPARABLE", "NOT_COMPARABLE", "summarize", "format_table", "write_report"]

# metric key -> column title
METRICS = {
    "top1": "R@1",
    "top2": "R@2",
    "top3": "R@3",
    "fid": "FID",
    "mm_dist": "MM-Dist",
    "diversity": "Diversity",
    "multimodality": "MModality",
}
COMPARABLE = "comparable with published tables (official evaluator checkpoint + GloVe)"
NOT_COMPARABLE = "NOT comparable (evaluator trained by us / random)"
_ROW_TITLES = {"ground_truth": "Real (ground truth)", "model": "Model"}


def summarize(per_row: dict[str, list[dict[str, float]]]) -> dict[str, dict[str, dict]]:
    """``{row: [replication {metric: value}]}`` -> ``{row: {metric: {mean, ci95, values}}}``."""
    summary = {}
    for row, replications in per_row.items():
        summary[row] = {}
        for metric in METRICS:
            values = [rep[metric] for rep in replications if metric in rep]
            if values:
                mean, half = confidence_interval(torch.tensor(values, dtype=torch.float64))
                summary[row][metric] = {"mean": float(mean), "ci95": float(half), "values": values}
    return summary


def format_table(summary: dict[str, dict[str, dict]], label: str, title: str = "T2M evaluation") -> str:
    """A fixed-width text table ``mean±ci`` per row and metric, headed by ``title`` and ``label``."""
    columns = [m for m in METRICS if any(m in metrics for metrics in summary.values())]
    repetitions = max((len(v["values"]) for metrics in summary.values() for v in metrics.values()), default=0)
    width = 16
    lines = [f"{title}: {repetitions} repetitions, mean ± 95% interval; {label}"]
    lines.append(f"{'':<20}" + "".join(f"{METRICS[m]:>{width}}" for m in columns))
    for row, metrics in summary.items():
        cells = []
        for m in columns:
            cells.append(f"{metrics[m]['mean']:.3f}±{metrics[m]['ci95']:.3f}" if m in metrics else "-")
        lines.append(f"{_ROW_TITLES.get(row, row):<20}" + "".join(f"{c:>{width}}" for c in cells))
    return "\n".join(lines)


def write_report(
    folder: str | PathLike[str], summary: dict[str, dict[str, dict]], label: str, protocol: dict
) -> tuple[Path, Path]:
    """Write ``t2m_evaluation.json`` (everything) and ``t2m_evaluation.csv`` (row, metric, mean, ci95, n)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    json_path, csv_path = folder / "t2m_evaluation.json", folder / "t2m_evaluation.csv"
    report = {"label": label, "comparable": label == COMPARABLE, "protocol": protocol, "rows": summary}
    with atomic_open(json_path, "w", encoding="utf-8") as f:
        f.write(json.dumps(report, indent=2))
    with atomic_open(csv_path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["row", "metric", "mean", "ci95", "repetitions"])
        for row, metrics in summary.items():
            for metric, value in metrics.items():
                writer.writerow([row, metric, value["mean"], value["ci95"], len(value["values"])])
    return json_path, csv_path
