"""Progress of long work: :class:`Progress` is a ``tqdm`` with the project's settings (stderr; a live bar
on a terminal; off a terminal a plain line every ``every`` seconds and one at the end, never a carriage
return; nothing when quiet). What tqdm cannot know, it is told:

* items of unequal cost: tqdm counts their *weight* (expected cost, :func:`particle_weight`), the line
  shows the items done (``12/60 runs``);
* the ETA's rate is the weight done since the first item finished (the first carries one-time work:
  kernels loaded, data generated; its rate made the ETA 70x too long) over that time minus the time
  numba spent compiling kernels (once per machine, then cached: :func:`compile_seconds`).

:class:`Loading` is the heartbeat of one slow file load (a tqdm too, refreshed by a thread).
"""

from __future__ import annotations

import logging
import shutil
import sys
import threading
import time

from tqdm import tqdm

_CLOCK = {"depth": 0, "start": 0.0, "total": 0.0, "listening": False}  # numba's outermost compilations


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
    """One-line notes: on a terminal tqdm erases its bars first and draws them again below the note."""

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


class _Settings(tqdm):
    """tqdm with the project's settings: stderr, disabled when quiet, drawn by tqdm on a terminal; off a
    terminal every display is one plain line (no carriage return, no padding) and closing adds none."""

    monitor_interval = 0  # no monitor thread

    def __init__(self, stream, label: str, quiet: bool, every: float, fmt: tuple[str, str], **kw):
        stream = stream or sys.stderr
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        super().__init__(
            file=stream,
            desc=label,
            disable=quiet,
            bar_format=fmt[0] if self.tty else fmt[1],
            ascii=" 123456789#",
            ncols=min(shutil.get_terminal_size((100, 24)).columns or 100, 120) if self.tty else 10**6,
            mininterval=0.2 if self.tty else every,
            miniters=0,
            delay=1e-9,  # nothing drawn before the first update
            smoothing=0,  # the ETA's rate is ours (format_dict)
            nrows=1000,  # a terminal of unknown height (a pty of 0 rows) would hide the bar
            leave=self.tty,
            **kw,
        )

    def display(self, msg=None, pos=None):
        if self.tty:
            return super().display(msg, pos)
        if msg is None:  # off a terminal: a line of its own; clearing (msg '') writes nothing
            self.fp.write(str(self) + "\n")
            self.fp.flush()
        return False

    def refresh(self, nolock=False, lock_args=None):
        if not self.disable:
            self.last_print_t = self._time()  # something is shown (tqdm's close looks)
        return super().refresh(nolock, lock_args)

    def clear(self, nolock=False):
        if self.tty:  # a line written off a terminal stays
            super().clear(nolock)


class Progress(_Settings):
    """``start(total, total_weight)`` once the work is known, ``update(n, failed=, weight=)`` after each
    finished item, ``close()`` at the end (module docstring). ``done``/``total`` count items,
    ``weight_done``/``total_weight`` their weights (tqdm's ``n`` and its total)."""

    def __init__(
        self, total=0, quiet=False, stream=None, every=10.0, *, label="progress", unit="unit", total_weight=None
    ):
        self.done = self.failed = 0
        self.items, self.unit_name, self.first = total, unit, None  # first: (time, compile s, weight)
        self.c0 = compile_seconds()
        tail = "elapsed {elapsed_s:.0f} s{compiling}{eta}{postfix}"
        fmt = (
            "{desc}: {percentage:3.0f}%|{bar}| {count} [" + tail + "]",
            "{desc}: {count} ({percentage:.0f} % of the work), " + tail,
        )
        super().__init__(stream, label, quiet, every, fmt, total=float(total if total_weight is None else total_weight))

    total_weight = property(lambda self: self.total)
    weight_done = property(lambda self: self.n)

    def start(self, total: int, total_weight: float | None = None) -> None:
        """Set the amount of work once it is known (before the first update)."""
        self.items, self.total = total, float(total if total_weight is None else total_weight)
        _listen()  # the work's modules are imported by now: numba too if it compiles

    def update(self, n: int = 1, failed: int = 0, weight: float | None = None):
        self.done += n
        self.failed += failed
        w = float(n if weight is None else weight)
        if self.disable:  # quiet: counted, never drawn (tqdm's update would not count)
            self.n += w
            return
        first = self.first is None
        if first:
            now = time.monotonic()
            self.first = (now, compile_seconds(now), self.n + w)
        if not (first and self.tty) and self.items and self.done < self.items:
            return super().update(w)
        self.n += w  # the end, and a terminal's first item: drawn now
        self.refresh()
        self.last_print_n = self.n

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
        now, done = time.monotonic(), min(self.done, self.items) if self.items else self.done
        eta, c = self.eta(now), compile_seconds(now) - self.c0
        fail = f", {self.failed} failed" if self.failed else ""
        d["count"] = f"{done}/{self.items} {self.unit_name}s{fail}"
        d["compiling"] = f", {c:.0f} s compiling kernels" if c >= 0.5 else ""
        d["eta"] = f", ETA {eta:.0f} s" if eta == eta else ""
        d["n"] = min(d["n"], d["total"]) if d["total"] else 1.0
        d["total"] = d["total"] or 1.0  # nothing to do: done
        return d


class Loading(_Settings):
    """A heartbeat while one file is read (``with Loading(label, size):`` around the adapter's call):
    nothing for ``after`` seconds, then (a thread refreshing it) the file, its size, the elapsed time and
    the stage the adapter last named (:func:`load_stage`, with its share of the work and the ETA from
    it) every second on a terminal, every ``every`` seconds otherwise, and a closing line. ``quiet``
    None: quiet when the notes of the logger ``replay`` are off (the CLI's ``-q``)."""

    active: list = []  # the loads in progress, innermost last (load_stage talks to the last)

    def __init__(self, label, size=None, quiet=None, stream=None, after=3.0, every=10.0):
        if quiet is None:
            quiet = not logging.getLogger("replay").isEnabledFor(logging.INFO)
        self.stage, self.share, self.shown, self.after, self.end = "", None, False, after, ""
        head = f"load {label}" + ("" if size is None else f" ({_bytes(size)})")
        fmt = "{desc}: {elapsed_s:.0f} s{postfix}"
        super().__init__(stream, head, quiet, every, (fmt, fmt), total=1.0)
        self._stop, self.every = threading.Event(), every

    def __enter__(self):
        Loading.active.append(self)
        if not self.disable:
            threading.Thread(target=self._beat, name="replay-loading", daemon=True).start()
        return self

    def __exit__(self, kind, *_):
        Loading.active.remove(self)
        self._stop.set()
        if self.shown:
            with self._lock:
                self.end = "done" if kind is None else "stopped"
                self.refresh(nolock=True)
        self.close()
        return False

    @property
    def format_dict(self):
        d, el = super().format_dict, self._time() - self.start_t
        d["postfix"] = f", {self.stage}" if self.stage else ""
        if self.share:
            d["postfix"] += f" ({100 * self.share:.0f} % of the work, ETA {el / self.share * (1 - self.share):.0f} s)"
        if self.end:
            d["bar_format"] = f"{{desc}}: {self.end} in {{elapsed_s:.0f}} s"
        return d

    def _beat(self) -> None:
        wait = self.after
        while not self._stop.wait(wait):
            with self._lock:
                if not self._stop.is_set():
                    self.refresh(nolock=True)
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
