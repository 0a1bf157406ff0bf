"""Exceptions that the ``sm`` command reports as a one-paragraph message instead of a traceback."""

from __future__ import annotations


class DatasetNotFoundError(FileNotFoundError):
    """A data module's files are missing.

    The message says where the data is expected and which command (``sm prepare ...``) builds it;
    ``sm fit|validate|test|predict`` prints it and exits with status 2.
    """
