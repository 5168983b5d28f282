"""Exceptions that reach the user as a one-line message."""

from __future__ import annotations


class CalibError(ValueError):
    """An error the user can fix: bad input, bad config, missing file.

    The message must be one line saying what is wrong, where, and how to fix it.
    The CLI prints it as ``error: <message>`` and exits with status 2; no traceback
    is shown unless ``--debug`` is given. A ``ValueError``, so library users can
    catch it like any invalid-argument error.
    """
