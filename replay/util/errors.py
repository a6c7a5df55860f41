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


SHOWN = 60  # characters of a user's value an error message quotes at most


def shown(value, limit: int = SHOWN) -> str:
    """``repr(value)`` for an error message, at most about ``limit`` characters: a longer value
    (a 100 MB string in a mapping) is quoted by its start and its length, never echoed whole."""
    if isinstance(value, str) and len(value) > limit:
        return f"{value[:limit]!r}... ({len(value)} characters)"
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def bounded(message: str, limit: int = 2000) -> str:
    """An error message as printed: at most ``limit`` characters (the backstop of the CLI's error
    line, whatever a message quotes)."""
    text = str(message)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters in all)"


def listed(items, limit: int = SHOWN, most: int = 12) -> str:
    """Names for an error message, comma-separated: a short name as it is, a long one by
    :func:`shown`, at most ``most`` of them (then how many more)."""
    items = list(items)
    text = ", ".join(x if isinstance(x, str) and len(x) <= limit else shown(x, limit) for x in items[:most])
    return text + (f" and {len(items) - most} more" if len(items) > most else "")
