"""Pieces of a download that need nothing of the project: URL checks, printable server text,
the wall-clock budget of a download (:class:`Deadline`), one-line network failure reasons, and
the temporary ``.part`` files of downloads (their owner, and the removal of stale ones).

A temporary file is named ``.<file>.<pid>@<host>.<random>.part``: the process that writes it
and the machine it runs on. A later download into the same directory removes the ones whose
process is gone (same host, process id no longer running), and those of an earlier version
(``.<file>.<random>.part``, no owner recorded) untouched for :data:`LEGACY_AGE` seconds; a
download still running is never touched.
"""

from __future__ import annotations

import http.client
import os
import re
import socket
import threading
import time
import urllib.parse
from pathlib import Path

from replay.util.errors import ReplayError

LEGACY_AGE = 24 * 3600.0  # s: an owner-less .part untouched this long is a killed download's
_OWNED = re.compile(r"^\..+\.(\d+)@([A-Za-z0-9_-]*)\.[A-Za-z0-9_]+\.part$")
_LEGACY = re.compile(r"^\..+\.[A-Za-z0-9_]{8}\.part$")


def printable(text, limit: int = 120) -> str:
    """``text`` (from a server: a status reason, a header) safe for one line of a terminal:
    whitespace runs become one space, other control and non-ASCII characters ``\\xNN``-style
    escapes, and it is cut to ``limit`` characters (marked ``…``)."""
    out = []
    for ch in " ".join(str(text).split()):
        out.append(ch if " " <= ch <= "~" else ch.encode("unicode_escape").decode("ascii"))
    line = "".join(out)
    return line if len(line) <= limit else line[: limit - 1] + "…"


def check_url(url: str, where: str) -> str:
    """``url`` when it is an absolute http(s) URL with a host (and a valid port), else a one-line
    ReplayError naming ``where`` (e.g. the environment variable it came from)."""
    try:
        parts = urllib.parse.urlsplit(url)
        parts.port  # noqa: B018 — raises ValueError for a port out of range or not a number
    except ValueError as e:
        raise ReplayError(f"{where} '{printable(url)}' is not a valid URL ({printable(e)})") from None
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ReplayError(
            f"{where} '{printable(url)}' is not an http(s) URL with a host (e.g. https://mirror.example.org/data)"
        )
    return url


class Deadline:
    """The wall-clock budget of one download: when it passes, the watched socket is shut down,
    which ends any wait on it (connect, TLS, headers, body)."""

    def __init__(self, seconds: float):
        self.seconds, self.expired, self._sock = seconds, False, None
        self.end = time.monotonic() + seconds
        self._lock = threading.Lock()
        self._timer = threading.Timer(seconds, self._expire)
        self._timer.daemon = True
        self._timer.start()

    def _expire(self):
        with self._lock:
            self.expired, sock = True, self._sock
        if sock is not None:
            shutdown(sock)

    def watch(self, sock):
        with self._lock:
            self._sock, expired = sock, self.expired
        if expired:
            shutdown(sock)

    @property
    def passed(self) -> bool:
        return self.expired or time.monotonic() >= self.end

    def left(self) -> float:
        """Seconds left (a connect attempt is not allowed to wait longer)."""
        if self.passed:
            raise TimeoutError
        return self.end - time.monotonic()

    def cancel(self):
        self._timer.cancel()


def shutdown(sock):
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass


def network_reason(e: Exception, timeout: float) -> str:
    """A short one-line reason for a network failure."""
    if isinstance(e, TimeoutError):
        return f"timed out after {timeout:g} s"
    if isinstance(e, http.client.IncompleteRead):
        return "connection closed before the end of the body"
    if isinstance(e, http.client.RemoteDisconnected):
        return "the server closed the connection without an answer"
    if isinstance(e, http.client.HTTPException):
        return f"not a valid HTTP answer ({type(e).__name__}: {printable(e, 80)})"
    return printable(getattr(e, "strerror", None) or str(e) or type(e).__name__, 200)


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname())[:40]


def part_prefix(name: str) -> str:
    """The prefix of this process's temporary files for ``name`` (``tempfile.mkstemp(prefix=...)``)."""
    return f".{name}.{os.getpid()}@{_host()}."


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # exists (another user's), or not a pid we can judge: leave it
    return True


def stale_parts(directory: Path) -> list[Path]:
    """The ``.part`` files in ``directory`` left by downloads that cannot be running any more."""
    out, host, now = [], _host(), time.time()
    try:
        entries = list(Path(directory).iterdir())
    except OSError:
        return []
    for path in entries:
        owned, legacy = _OWNED.match(path.name), _LEGACY.match(path.name)
        try:
            if not path.is_file() or path.is_symlink():
                continue
            if owned:
                if owned.group(2) == host and not _running(int(owned.group(1))):
                    out.append(path)
            elif legacy and now - path.stat().st_mtime > LEGACY_AGE:
                out.append(path)
        except OSError:
            continue
    return out


def remove_stale_parts(directory: Path) -> tuple[int, int]:
    """Remove :func:`stale_parts` of ``directory``: (files removed, bytes freed)."""
    count = size = 0
    for path in stale_parts(directory):
        try:
            n = path.stat().st_size
            path.unlink()
        except OSError:
            continue
        count, size = count + 1, size + n
    return count, size
