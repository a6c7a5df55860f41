"""Progress of long work, drawn by ``tqdm``: on stderr, a live bar on a terminal; off a terminal a plain
line every ``every`` seconds and one at the end, never a carriage return (:class:`_Lines`); nothing when
quiet. What is ours is what tqdm cannot know:

* items of unequal cost (:class:`Progress`): tqdm counts their *weight* (expected cost,
  :func:`particle_weight`), the line shows the items done (``12/60 runs``);
* the ETA's rate is the weight done since the first item finished (the first carries one-time work:
  kernels loaded, data generated; its rate made the ETA 70x too long) over that time minus the time
  numba spent compiling kernels (once per machine, then cached: :func:`compile_seconds`);
* a file load has no updates of its own: :class:`Loading` is its heartbeat (tqdm's ``delay``, its
  share and ETA; a thread ticks it, as tqdm's monitor thread only unsticks bars that count).
"""

from __future__ import annotations

import logging
import re
import shutil
import sys
import threading
import time

from tqdm import tqdm

# numba's outermost compilations, timed here: tqdm cannot tell one-time compiling from the work
_CLOCK = {"depth": 0, "start": 0.0, "total": 0.0, "listening": False}


def _listen() -> None:
    """Time numba's compilations (its ``numba:compile`` events) once numba is imported (never imported
    here: a download's progress does not load it)."""
    if _CLOCK["listening"] or "numba" not in sys.modules:
        return
    # lazy: only when numba is loaded already (start-up time of the CLI)
    from numba.core import event  # noqa: PLC0415

    class _Clock(event.Listener):
        def on_start(self, ev):
            _CLOCK["start"] = time.monotonic() if _CLOCK["depth"] == 0 else _CLOCK["start"]
            _CLOCK["depth"] += 1

        def on_end(self, ev):
            _CLOCK["depth"] = max(0, _CLOCK["depth"] - 1)
            _CLOCK["total"] += 0.0 if _CLOCK["depth"] else time.monotonic() - _CLOCK["start"]

    event.register("numba:compile", _Clock())
    _CLOCK["listening"] = True


def compile_seconds(now: float | None = None) -> float:
    """Seconds this process has spent compiling numba kernels (one under way counted up to ``now``)."""
    running = (now or time.monotonic()) - _CLOCK["start"] if _CLOCK["depth"] else 0.0
    return _CLOCK["total"] + max(0.0, running)


class NoteHandler(logging.StreamHandler):
    """One-line notes: on a terminal tqdm erases its bars first and draws them again below the note.
    Not tqdm's ``logging_redirect_tqdm``: a context manager around the work (this is installed once) that
    off a terminal would draw a progress line again after each note."""

    def emit(self, record):
        if not getattr(self.stream, "isatty", lambda: False)():
            return super().emit(record)
        with tqdm.external_write_mode(file=self.stream):
            super().emit(record)


# What a run costs besides its filter (the data generated or cut, the scoring, the per-step table),
# in units of a Kalman filter's run: measured on `replay eval sim/auv-sonar --runs 20` (a block of
# 20 runs of the CKF takes 37 ms, 8 ms of it in the filter) and Bohai at 1 Hz (a trial's EKF runs
# ~70 ms, the PF's with 1000 particles ~500 ms: 7x, not the 50x of the particles alone).
RUN_OVERHEAD = 4.0


def particle_weight(params: dict, runs: int) -> float:
    """Expected cost of ``runs`` runs of a filter with ``params``: per run, the work besides the filter
    (:data:`RUN_OVERHEAD`) plus the filter's, particles / 20 (or 1) x optimiser iterations (or 1)."""
    n = params.get("n_particles") or params.get("N") or 1
    it = params.get("t_max") or params.get("T_max") or params.get("iterations") or 1
    try:
        return float(runs) * (RUN_OVERHEAD + max(1.0, float(n) / 20.0) * max(1.0, float(it)))
    except (TypeError, ValueError):
        return float(runs) * (RUN_OVERHEAD + 1.0)


_CURSOR = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")  # a terminal's control sequence (tqdm's cursor moves)


class _Lines:
    """Off a terminal, what tqdm writes (``\\r``, the display, its padding) as plain lines; its clearing
    and closing write nothing (tqdm has no line mode), nor its cursor moves between two displays at
    once (a load's heartbeat under a run's bar: tqdm's ``moveto`` writes ``ESC [A``)."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text: str) -> None:
        line = _CURSOR.sub("", text).lstrip("\r").rstrip(" \n")
        if line:
            self.stream.write(line + "\n")

    def flush(self) -> None:
        self.stream.flush()


class _Settings(tqdm):
    """tqdm with the project's settings: stderr, disabled when quiet, a bar on a terminal (redrawn at
    most every 0.2 s), off it a line at most every ``every`` seconds."""

    monitor_interval = 0  # no monitor thread

    def __init__(self, stream, label: str, quiet: bool, every: float, fmt: tuple[str, str], leave=None, **kw):
        stream = stream or sys.stderr
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        super().__init__(
            file=stream if self.tty else _Lines(stream),
            desc=label,
            disable=quiet,
            bar_format=fmt[0] if self.tty else fmt[1],
            ascii=True,
            ncols=min(shutil.get_terminal_size((100, 24)).columns or 100, 120) if self.tty else 10**6,  # no cut
            mininterval=0.2 if self.tty else every,
            miniters=0,  # by time only (tqdm's dynamic miniters would skip items of unequal cost)
            smoothing=0,  # the ETA's rate is ours (format_dict)
            nrows=1000,  # a terminal of unknown height (a pty of 0 rows) would hide the bar
            leave=self.tty if leave is None else leave,  # None: off a terminal the end's line is the update's
            **kw,
        )


class Progress(_Settings):
    """``start(total, total_weight)`` once the work is known, ``update(n, failed=, weight=)`` after each
    finished item, ``close()`` at the end (module docstring). ``done``/``items`` count items,
    ``weight_done``/``total_weight`` their weights (tqdm's ``n`` and ``total``)."""

    def __init__(
        self, total=0, quiet=False, stream=None, every=10.0, *, label="progress", unit="unit", total_weight=None
    ):
        self.done = self.failed = 0
        self.items, self.first, self.c0 = total, None, compile_seconds()  # first: (time, compile s, weight)
        tail = "elapsed {elapsed_s:.0f} s{compiling}{eta}{postfix}"
        fmt = (
            "{desc}: {percentage:3.0f}%|{bar}| {count} {unit}s{failed} [" + tail + "]",
            "{desc}: {count} {unit}s{failed} ({percentage:.0f} % of the work), " + tail,
        )
        weight = float(total if total_weight is None else total_weight)
        super().__init__(
            stream, label, quiet, every, fmt, unit=unit, total=weight, delay=1e-9
        )  # nothing before an update

    total_weight = property(lambda self: self.total)
    weight_done = property(lambda self: self.n)

    def start(self, total: int, total_weight: float | None = None) -> None:
        """Set the amount of work once it is known (before the first update; tqdm's reset would draw)."""
        self.items, self.total = total, float(total if total_weight is None else total_weight)
        _listen()  # the work's modules are imported by now: numba too if it compiles

    def update(self, n: int = 1, failed: int = 0, weight: float | None = None):
        self.done += n
        self.failed += failed
        w = float(n if weight is None else weight)
        if self.disable:  # quiet: counted, never drawn (tqdm's update does not count then)
            self.n += w
            return
        now = time.monotonic()
        at_once = self.first is None and self.tty or not self.items or self.done >= self.items
        self.first = self.first or (now, compile_seconds(now), self.n + w)
        if not super().update(w) and at_once:  # a terminal's first item and the end: drawn now
            self.refresh()
            self.last_print_n, self.last_print_t = self.n, self._time()  # what tqdm's update does after drawing

    def eta(self, now=None) -> float:
        """Seconds left: the weight left over the rate since the first item (compilations left out); NaN
        until a second item is done."""
        now = now or time.monotonic()
        if self.first is None or self.n <= self.first[2]:
            return float("nan")
        t1, c1, w1 = self.first
        el = max(1e-9, now - t1 - (compile_seconds(now) - c1))
        return el / (self.n - w1) * max(0.0, self.total - self.n)

    @property
    def format_dict(self):
        d = super().format_dict
        now = time.monotonic()
        eta, c = self.eta(now), compile_seconds(now) - self.c0
        d["count"] = f"{min(self.done, self.items) if self.items else self.done}/{self.items}"
        d["failed"] = f", {self.failed} failed" if self.failed else ""
        d["compiling"] = f", {c:.0f} s compiling kernels" if c >= 0.5 else ""
        d["eta"] = f", ETA {eta:.0f} s" if eta == eta else ""
        d["n"] = min(d["n"], d["total"]) if d["total"] else 1.0  # never past the total; nothing to do: done
        d["total"] = d["total"] or 1.0
        return d


class Loading(_Settings):
    """A heartbeat while one file is read (``with Loading(label, size):`` around the adapter's call):
    nothing for ``after`` seconds (tqdm's ``delay``), then the file, its size, the elapsed time and the
    stage the adapter last named (:func:`load_stage`, with its share of the work and tqdm's ETA from
    it) every second on a terminal, every ``every`` seconds otherwise, and a closing line. ``quiet``
    None: quiet when the notes of the logger ``replay`` are off (the CLI's ``-q``)."""

    active: list = []  # the loads in progress, innermost last (load_stage talks to the last)
    FORMAT = "{desc}: {elapsed_s:.0f} s{postfix}"
    SHARE = " ({percentage:.0f} % of the work, ETA {remaining_s:.0f} s)"

    def __init__(self, label, size=None, quiet=None, stream=None, after=3.0, every=10.0):
        if quiet is None:
            quiet = not logging.getLogger("replay").isEnabledFor(logging.INFO)
        head = f"load {label}" + ("" if size is None else f" ({tqdm.format_sizeof(size, 'B')})")
        fmt = (self.FORMAT, self.FORMAT)
        super().__init__(stream, head, quiet, 0.0, fmt, total=1.0, delay=after, leave=True)
        self.every, self._stop, self._thread = 1.0 if self.tty else every, threading.Event(), None

    def __enter__(self):
        Loading.active.append(self)
        if not self.disable:
            self._thread = threading.Thread(target=self._beat, name="replay-loading", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, kind, *_):
        Loading.active.remove(self)
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.bar_format = f"{{desc}}: {'done' if kind is None else 'stopped'} in {{elapsed_s:.0f}} s"
        self.close()  # the closing line, if anything was shown (tqdm's delay)
        return False

    def _beat(self) -> None:
        wait = self.delay
        while not self._stop.wait(wait):
            self.update(0)  # drawn once the delay has passed
            wait = self.every


def load_stage(stage: str, share: float | None = None) -> None:
    """Name what the adapter is doing now (and the share of its work done before it, 0-1) for the
    heartbeat of the innermost :class:`Loading`; nothing when none is active."""
    if Loading.active:
        ld = Loading.active[-1]
        ld.n = ld.last_print_n = share or 0.0  # set, not counted: tqdm's percentage and ETA from it
        ld.set_postfix_str(stage, refresh=False)
        ld.bar_format = Loading.FORMAT + (Loading.SHARE if share else "")
