"""Progress of long work, drawn by tqdm (:class:`_Bar`): a live bar on a terminal, one plain line
every ~10 s otherwise (a log reads line by line), nothing quiet. What is ours is what tqdm cannot know:

Work comes in items of unequal cost: each item carries a weight (its expected cost,
e.g. runs x (4 + particles / 20)), and the ETA extrapolates the time per unit of weight
done since the first item finished to the weight left — heavy items last do not make it
lie, and the first item's one-time work (kernels loaded, data generated) does not make it
70x too long. Time spent compiling
numba kernels (once per machine, then cached: tens of seconds on a first run) is no
work done: it is left out of that rate (:func:`compile_seconds`) and shown apart; while
it lasts the bar says so instead of an ETA. Notes logged meanwhile (:class:`NoteHandler`)
take their own line, not the bar's (tqdm's ``external_write_mode``).
"""

from __future__ import annotations

import logging
import shutil
import sys
import threading
import time

from tqdm import tqdm

_CLOCK = {"depth": 0, "start": 0.0, "total": 0.0, "listening": False}  # numba's outermost compilations
_LOCK = threading.Lock()
_BAR: dict = {"live": None}  # the Progress whose bar is on the terminal


def _listen() -> None:
    """Time numba's compilations from now on (its ``numba:compile`` events, outermost only), once
    numba is imported (never imported here: a download's progress does not load it)."""
    if _CLOCK["listening"] or "numba" not in sys.modules:
        return
    from numba.core import event

    class _Clock(event.Listener):
        def on_start(self, ev):
            with _LOCK:
                first = _CLOCK["depth"] == 0
                if first:
                    _CLOCK["start"] = time.monotonic()
                _CLOCK["depth"] += 1
            bar = _BAR["live"]
            if first and bar is not None:
                bar._draw(final=True)  # "compiling kernels..." instead of an ETA

        def on_end(self, ev):
            with _LOCK:
                _CLOCK["depth"] = max(0, _CLOCK["depth"] - 1)
                if _CLOCK["depth"] == 0:
                    _CLOCK["total"] += time.monotonic() - _CLOCK["start"]

    event.register("numba:compile", _Clock())
    _CLOCK["listening"] = True


def compile_seconds(now: float | None = None) -> float:
    """Seconds this process has spent compiling numba kernels since :func:`_listen` (a compilation
    under way counted up to ``now``)."""
    with _LOCK:
        running = (now or time.monotonic()) - _CLOCK["start"] if _CLOCK["depth"] else 0.0
        return _CLOCK["total"] + max(0.0, running)


def compiling() -> bool:
    """Whether numba is compiling now (in any thread of this process)."""
    return _CLOCK["depth"] > 0


class NoteHandler(logging.StreamHandler):
    """A logging handler for one-line notes: on a terminal, tqdm erases its live bars on this stream
    first and draws them again below the note (:meth:`tqdm.external_write_mode`), so a note never
    lands on a bar's line; elsewhere a progress line is a line of its own already."""

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


class _Bar(tqdm):
    """tqdm drawing only when told (:meth:`refresh`): the label, then (on a terminal, when ``bar``) the
    share of the weight done and ``#`` cells, then a tail of ours (:class:`Progress`'s ETA leaves out
    the first item and the compilations, which tqdm's rate would not). On a terminal tqdm redraws its
    line in place; elsewhere (a log, a pipe) each refresh is one plain line of its own."""

    monitor_interval = 0  # no monitor thread: nothing draws but refresh

    def __init__(self, stream, label: str, bar: bool):
        self.tail = ""
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        super().__init__(
            total=1.0,
            file=stream,
            desc=label,
            bar_format="{desc}: {percentage:3.0f}%|{bar}|{tail}" if bar and self.tty else "{desc}: {tail}",
            ascii=" 123456789#",
            ncols=min(shutil.get_terminal_size((100, 24)).columns or 100, 120) if self.tty else 10**6,
            delay=float("inf"),  # never drawn by tqdm itself (every refresh is ours)
            nrows=1000,  # a terminal of unknown height (a pty of 0 rows) would make tqdm hide its one bar
            leave=False,  # the last line is finished by its owner (:meth:`end`)
        )

    @property
    def format_dict(self):
        return {**super().format_dict, "tail": self.tail}

    def display(self, msg=None, pos=None):
        if self.tty:
            return super().display(msg, pos)
        if msg is None:  # off a terminal: the line on a line of its own (no carriage return, no padding)
            self.fp.write(str(self) + "\n")
            self.fp.flush()
        return True

    def clear(self, nolock=False):
        if self.tty:  # a line written off a terminal stays
            super().clear(nolock)

    def end(self) -> None:
        """Finish the terminal's line (the next output starts below it), then close."""
        if self.tty:
            self.fp.write("\n")
            self.fp.flush()
        self.close()


class Progress:
    """``update(n, weight=...)`` after each finished item; ``close()`` at the end. Drawn by tqdm
    (:class:`_Bar`): a live bar on a terminal redrawn at most 5 times a second, one plain line every
    ``every`` seconds (and at the end) otherwise, nothing when ``quiet``."""

    def __init__(
        self,
        total: int,
        quiet: bool = False,
        stream=None,
        every: float = 10.0,
        *,
        label: str = "progress",
        unit: str = "unit",
        total_weight: float | None = None,
    ):
        self.total, self.quiet, self.every, self.label, self.unit = total, quiet, every, label, unit
        self.total_weight = float(total_weight if total_weight is not None else total)
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.done = self.failed = 0
        self.weight_done = 0.0
        self.first = None  # (time, compile seconds, weight done) when the first item finished
        self._tq = None  # tqdm's display, opened at the first draw
        self._drawn = 0.0
        self.t0 = self.last = time.monotonic()
        self.c0 = compile_seconds(self.t0)

    @property
    def bar(self) -> bool:
        """Whether the display is a live bar (on a terminal, not quiet, the amount of work known)."""
        return bool(not self.quiet and self.total and self.tty)

    def start(self, total: int, total_weight: float | None = None) -> None:
        """Set the amount of work once it is known (before the first update)."""
        self.total = total
        self.total_weight = float(total_weight if total_weight is not None else total)
        _listen()  # the work's modules are imported by now: numba too if it compiles

    def _show(self, tail: str) -> None:
        """tqdm draws the label, (on a terminal) the weighted share and its cells, then ``tail``."""
        if self._tq is None:
            self._tq = _Bar(self.stream, self.label, bar=True)
        if self.tty:
            _BAR["live"] = self
        self._tq.total = self.total_weight or 1.0
        self._tq.n = min(self.weight_done, self._tq.total) if self.total_weight else 1.0
        if self._tq is None:  # opened at the first line (a note before it redraws nothing)
            self._tq = _Bar(self.stream, self._head(), bar=False)
        self._tq.tail = tail
        self._tq.refresh()

    def _tail(self, now: float) -> str:
        """What follows the bar: the count, failures, the elapsed time and the ETA (or that kernels compile)."""
        eta = self.eta(now)
        fail = f", {self.failed} failed" if self.failed else ""
        return f" {self._count()} {self.unit}s{fail} [{now - self.t0:.0f} s" + (
            ", compiling kernels (one time, cached)...]"
            if compiling()
            else self._compiling(now) + (f", ETA {eta:.0f} s]" if eta == eta else "]")
        )

    def _draw(self, final: bool = False) -> None:
        """The terminal's bar, redrawn in place at most 5 times a second."""
        now = time.monotonic()
        if not final and now - self._drawn < 0.2:
            return
        self._drawn = now
        self._show(self._tail(now))

    def update(self, n: int = 1, failed: int = 0, weight: float | None = None) -> None:
        w = float(n if weight is None else weight)
        self.done += n
        self.failed += failed
        self.weight_done += w
        if self.first is None:
            now = time.monotonic()
            self.first = (now, compile_seconds(now), self.weight_done)
        if self.quiet:
            return
        if self.bar:
            self._draw(final=self.done >= self.total)
            return
        now = time.monotonic()
        if now - self.last >= self.every or self.done >= self.total:
            self.last = now
            self._show(self._body(now))

    def eta(self, now=None) -> float:
        """Seconds left: time per unit of weight done since the first item finished, times the weight
        left (NaN until a second item is done). The first item is left out of the rate: it carries the
        one-time work (kernels loaded from the cache, data read or generated: 0.8 s of the 1.4 s of
        ``replay eval sim/auv-sonar --runs 20``, whose first ETA was 74x the time left). The time spent
        compiling kernels (once per machine) is not counted as work done either."""
        now = now or time.monotonic()
        if self.first is None or self.weight_done <= self.first[2]:
            return float("nan")
        t1, c1, w1 = self.first
        el = max(0.0, now - t1 - (compile_seconds(now) - c1))
        return el / (self.weight_done - w1) * max(0.0, self.total_weight - self.weight_done)

    def _compiling(self, now) -> str:
        """``", N s compiling kernels"`` when some of the elapsed time was (one-time) compilation."""
        c = compile_seconds(now) - self.c0
        return f", {c:.0f} s compiling kernels" if c >= 0.5 else ""

    def _body(self, now) -> str:
        """The plain line after its label: the count, the share of the work, failures, times."""
        pct = min(100.0, 100.0 * self.weight_done / self.total_weight) if self.total_weight else 100.0
        fail = f", {self.failed} failed" if self.failed else ""
        eta = self.eta(now)
        return (
            f"{self._count()} {self.unit}s ({pct:.0f} % of the work){fail}, "
            f"elapsed {now - self.t0:.0f} s{self._compiling(now)}" + (f", ETA {eta:.0f} s" if eta == eta else "")
        )

    def line(self, now=None) -> str:
        """The plain line (off a terminal): ``label: body``."""
        return f"{self.label}: {self._body(now or time.monotonic())}"

    def _count(self) -> str:
        """``done/total``, never past the total (a caller's count that overshoots is its bug, not shown)."""
        return f"{min(self.done, self.total) if self.total else self.done}/{self.total}"

    def close(self) -> None:
        if self._tq is not None:
            if self.bar and self.done:
                self._draw(final=True)
            self._tq.end()
            self._tq = None
        if _BAR["live"] is self:
            _BAR["live"] = None


class Loading:
    """A heartbeat while one file is read (``with Loading(label, size):`` around the adapter's call).

    Silent for the first ``after`` seconds: short loads print nothing. Then, on ``stream`` (stderr),
    a live line on a terminal or one plain line every ``every`` seconds: the file, its size, the
    elapsed time and the stage the adapter last named (:func:`load_stage`; with its share of the
    work, when it gives one, and the ETA from it), and a closing line. Quiet when ``quiet`` is
    true; None means "the notes of the logger ``replay`` are off" (the CLI's ``-q``; a library
    caller sees nothing unless it enables that logger at level INFO).
    """

    active: list = []  # the loads in progress, innermost last (load_stage talks to the last)

    def __init__(
        self,
        label: str,
        size: int | None = None,
        quiet: bool | None = None,
        stream=None,
        after: float = 3.0,
        every: float = 10.0,
    ):
        if quiet is None:
            quiet = not logging.getLogger("replay").isEnabledFor(logging.INFO)
        self.label, self.size, self.quiet, self.after, self.every = label, size, quiet, after, every
        self.stream = stream or sys.stderr
        self.stage, self.share = "", None
        self.shown = False
        self.t0 = time.monotonic()
        self._thread = self._stop = self._tq = None

    def __enter__(self):
        Loading.active.append(self)
        if not self.quiet:
            self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
            self._stop = threading.Event()
            self._thread = threading.Thread(target=self._beat, name="replay-loading", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, kind, *_):
        if self in Loading.active:
            Loading.active.remove(self)
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            if self.shown:
                el = time.monotonic() - self.t0
                end = "done" if kind is None else "stopped"
                self._write(f"{end} in {el:.0f} s")
            if self._tq is not None:
                self._tq.end()
        return False

    def _head(self) -> str:
        size = "" if self.size is None else f" ({_bytes(self.size)})"
        return f"load {self.label}{size}"

    def line(self, now=None) -> str:
        return f"{self._head()}: {self._body(now)}"

    def _body(self, now=None) -> str:
        el = (now or time.monotonic()) - self.t0
        text = f"{el:.0f} s"
        if self.stage:
            text += f", {self.stage}"
        if self.share:
            text += f" ({100 * self.share:.0f} % of the work, ETA {el / self.share * (1 - self.share):.0f} s)"
        return text

    def _write(self, tail: str) -> None:
        """tqdm draws ``head: tail`` (in place on a terminal, a line of its own elsewhere)."""
        if self._tq is None:  # opened at the first line (a note before it redraws nothing)
            self._tq = _Bar(self.stream, self._head(), bar=False)
        self._tq.tail = tail
        self._tq.refresh()

    def _beat(self) -> None:
        wait = self.after
        while not self._stop.wait(wait):
            self._write(self._body())
            self.shown = True
            wait = 1.0 if self.tty else self.every


def load_stage(stage: str, share: float | None = None) -> None:
    """Name what the adapter is doing now (and the share of its work done before it, 0-1) for the
    heartbeat of the innermost :class:`Loading`; nothing when none is active."""
    if Loading.active:
        Loading.active[-1].stage, Loading.active[-1].share = stage, share


def _bytes(n: int) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"
