"""Errors that reach the user as one line, never as a traceback."""


class ReplayError(Exception):
    """A problem with the user's input or environment.

    The CLI prints ``str(err)`` on one line to stderr and exits with status 2.
    The message must name the file, row, topic or dataset and say what is wrong.
    """


class DataError(ReplayError):
    """A data file is missing, unreadable or does not hold what it must."""

    def __init__(self, source, what: str, row: int | None = None):
        self.source = str(source)
        self.row = row
        where = self.source if row is None else f"{self.source}, row {row}"
        super().__init__(f"{where}: {what}")


class ProtocolError(ReplayError):
    """A filter broke the filter protocol (``filters/base.py``): it returned a state or a
    covariance of the wrong shape, or the wrong number of runs. That filter's runs are
    failed (their error recorded); the other filters' results stand."""
