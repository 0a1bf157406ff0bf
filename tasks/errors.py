"""Exceptions that the ``sm`` command reports as a one-paragraph message instead of a traceback."""

from __future__ import annotations


class DatasetNotFoundError(FileNotFoundError):
    """A data module's files are missing.

    The message says where the data is expected and which command (``sm prepare ...``) builds it;
    ``sm fit|validate|test|predict`` prints it and exits with status 2.
    """


class DataFileError(ValueError):
    """A data file is malformed or holds values the project refuses (NaN, Inf, absurd counts or rates).

    The message names the file and where in it (line, frame, key). Every reader's own error type
    (``SkeletonFileError``, ``KineticsFileError``, ``AnnotationFileError``, ``BvhError``,
    ``MotionFileError``, ...) derives from it, so a command can catch the whole class at once.
    """
