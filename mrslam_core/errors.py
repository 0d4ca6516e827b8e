"""The base class of errors in what a user gave: a path, a file's content, a value."""

from __future__ import annotations


class InputError(Exception):
    """A user's input that cannot be used (a missing or wrong path, a value out of range, a file
    that is not what it should be). The ``mrslam`` command reports it in one line naming the
    problem and exits with status 2; every other exception is a bug and keeps its traceback."""
