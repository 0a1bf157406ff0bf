"""The model summary a run prints first: the layers, their parameters and mode, the totals; FLOPs only
when they were counted.

Lightning counts FLOPs only on a forward pass of the module's ``example_input_array``, which no task sets,
so its summary showed a FLOPs column of zeros and ``Total FLOPs: 0`` on every fit. :class:`ParameterSummary`
is Lightning's summary callback with its own table: the FLOPs column and total appear when a module does
count them, and plain text (no box drawing) reads the same on a terminal and in a log file. ``sm fit``
installs it unless the recipe configures a summary or turns it off (:func:`with_parameter_summary`).
"""

from __future__ import annotations

from collections.abc import Sequence

from lightning.pytorch.callbacks import Callback, ModelSummary
from lightning.pytorch.utilities import rank_zero_info
from lightning.pytorch.utilities.model_summary import get_formatted_model_size, get_human_readable_count

__all__ = ["ParameterSummary", "summary_table", "with_parameter_summary"]


def summary_table(
    columns: Sequence[tuple[str, Sequence[str]]],
    total_parameters: int,
    trainable_parameters: int,
    model_size: float,
    training_modes: dict[str, int],
    total_flops: int = 0,
) -> str:
    """``columns`` ((header, cells) each) as a left-aligned table, then the totals (FLOPs when counted)."""
    widths = [max([len(header), *(len(str(cell)) for cell in cells)]) for header, cells in columns]
    rows = [[header for header, _ in columns], *zip(*(cells for _, cells in columns))]
    lines = [" | ".join(f"{str(cell):<{w}}" for cell, w in zip(row, widths)).rstrip() for row in rows]
    rule = "-" * max(len(line) for line in lines)
    totals = [
        (get_human_readable_count(trainable_parameters), "Trainable params"),
        (get_human_readable_count(total_parameters - trainable_parameters), "Non-trainable params"),
        (get_human_readable_count(total_parameters), "Total params"),
        (get_formatted_model_size(model_size), "Total estimated model params size (MB)"),
        (str(training_modes.get("train", 0)), "Modules in train mode"),
        (str(training_modes.get("eval", 0)), "Modules in eval mode"),
    ]
    if total_flops:
        totals.append((get_human_readable_count(total_flops), "Total FLOPs"))
    return "\n".join([lines[0], rule, *lines[1:], rule, *(f"{value:<10} {name}" for value, name in totals)])


class ParameterSummary(ModelSummary):
    """Lightning's :class:`~lightning.pytorch.callbacks.ModelSummary` printing :func:`summary_table`."""

    @staticmethod
    def summarize(
        summary_data: list[tuple[str, list[str]]],
        total_parameters: int,
        trainable_parameters: int,
        model_size: float,
        total_training_modes: dict[str, int],
        total_flops: int,
        **summarize_kwargs,
    ) -> None:
        columns = [(name, cells) for name, cells in summary_data if name != "FLOPs" or total_flops]
        table = summary_table(
            columns, total_parameters, trainable_parameters, model_size, total_training_modes, total_flops
        )
        rank_zero_info("\n" + table)


def with_parameter_summary(
    callbacks: Sequence[Callback], enable_model_summary: bool | None
) -> tuple[list[Callback], bool | None]:
    """``callbacks`` plus :class:`ParameterSummary`, unless one is configured or summaries are turned off,
    and the trainer's ``enable_model_summary``: False once ours is added (Lightning's own switch adds its
    summary, or logs that it skipped it because one is configured)."""
    callbacks = list(callbacks)
    if enable_model_summary is False or any(isinstance(c, ModelSummary) for c in callbacks):
        return callbacks, enable_model_summary
    return [*callbacks, ParameterSummary()], False
