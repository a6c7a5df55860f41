"""Progress of long work: a live bar on a terminal, one plain line every ~10 s otherwise, nothing quiet.

Work comes in items of unequal cost: each item carries a weight (its expected cost,
e.g. runs x particles), and the ETA extrapolates the time per unit of weight done so
far to the weight left — heavy items last do not make it lie.
"""
from __future__ import annotations

import sys
import time


def particle_weight(params: dict, runs: int) -> float:
    """Expected cost of ``runs`` runs of a filter with ``params``: particles (or 1) x optimiser
    iterations (or 1) x runs — the dominant factors of a step's cost."""
    n = params.get("n_particles") or params.get("N") or 1
    it = params.get("t_max") or params.get("T_max") or params.get("iterations") or 1
    try:
        return float(runs) * max(1.0, float(n) / 20.0) * max(1.0, float(it))
    except (TypeError, ValueError):
        return float(runs)


class Progress:
    """``update(n, weight=...)`` after each finished item; ``close()`` at the end."""

    def __init__(self, total: int, quiet: bool = False, stream=None, every: float = 10.0, *,
                 label: str = "progress", unit: str = "unit", total_weight: float | None = None):
        self.total, self.quiet, self.every, self.label, self.unit = total, quiet, every, label, unit
        self.total_weight = float(total_weight if total_weight is not None else total)
        self.stream = stream or sys.stderr
        self.done = self.failed = 0
        self.weight_done = 0.0
        self.t0 = self.last = time.monotonic()
        self.bar = None
        self._open()

    def start(self, total: int, total_weight: float | None = None) -> None:
        """Set the amount of work once it is known (before the first update)."""
        self.total = total
        self.total_weight = float(total_weight if total_weight is not None else total)
        self._open()

    def _open(self) -> None:
        self.bar = bool(not self.quiet and self.total and getattr(self.stream, "isatty", lambda: False)())
        self._drawn = 0.0

    def _draw(self, final: bool = False) -> None:
        """The bar on one terminal line, redrawn in place (at most 5 times a second)."""
        now = time.monotonic()
        if not final and now - self._drawn < 0.2:
            return
        self._drawn = now
        import shutil

        cols = min(shutil.get_terminal_size((100, 24)).columns or 100, 120)
        frac = min(1.0, self.weight_done / self.total_weight) if self.total_weight else 1.0
        eta = self.eta(now)
        fail = f", {self.failed} failed" if self.failed else ""
        tail = (f" {self.done}/{self.total} {self.unit}s{fail} [{now - self.t0:.0f} s"
                + (f", ETA {eta:.0f} s]" if eta == eta else "]"))
        head = f"{self.label}: {100 * frac:3.0f}%|"
        width = max(10, cols - len(head) - len(tail) - 2)
        fill = int(round(frac * width))
        self.stream.write("\r" + head + "#" * fill + " " * (width - fill) + "|" + tail)
        self.stream.flush()

    def update(self, n: int = 1, failed: int = 0, weight: float | None = None) -> None:
        w = float(n if weight is None else weight)
        self.done += n
        self.failed += failed
        self.weight_done += w
        if self.quiet:
            return
        if self.bar:
            self._draw(final=self.done >= self.total)
            return
        now = time.monotonic()
        if now - self.last >= self.every or self.done >= self.total:
            self.last = now
            self.stream.write(self.line(now) + "\n")
            self.stream.flush()

    def eta(self, now=None) -> float:
        """Seconds left: elapsed time per unit of weight done, times the weight left."""
        el = (now or time.monotonic()) - self.t0
        if self.weight_done <= 0:
            return float("nan")
        return el / self.weight_done * max(0.0, self.total_weight - self.weight_done)

    def line(self, now=None) -> str:
        now = now or time.monotonic()
        el = now - self.t0
        pct = 100.0 * self.weight_done / self.total_weight if self.total_weight else 100.0
        fail = f", {self.failed} failed" if self.failed else ""
        return (f"{self.label}: {self.done}/{self.total} {self.unit}s ({pct:.0f} % of the work){fail}, "
                f"elapsed {el:.0f} s, ETA {self.eta(now):.0f} s")

    def close(self) -> None:
        if self.bar and self.done:
            self._draw(final=True)
            self.stream.write("\n")
            self.stream.flush()
        self.bar = False


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

    def __init__(self, label: str, size: int | None = None, quiet: bool | None = None, stream=None,
                 after: float = 3.0, every: float = 10.0):
        if quiet is None:
            import logging

            quiet = not logging.getLogger("replay").isEnabledFor(logging.INFO)
        self.label, self.size, self.quiet, self.after, self.every = label, size, quiet, after, every
        self.stream = stream or sys.stderr
        self.stage, self.share = "", None
        self.shown = False
        self.t0 = time.monotonic()
        self._thread = self._stop = None

    def __enter__(self):
        Loading.active.append(self)
        if not self.quiet:
            import threading

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
                self._write(f"{self._head()}: {end} in {el:.0f} s", final=True)
        return False

    def _head(self) -> str:
        size = "" if self.size is None else f" ({_bytes(self.size)})"
        return f"load {self.label}{size}"

    def line(self, now=None) -> str:
        el = (now or time.monotonic()) - self.t0
        text = f"{self._head()}: {el:.0f} s"
        if self.stage:
            text += f", {self.stage}"
        if self.share:
            text += f" ({100 * self.share:.0f} % of the work, ETA {el / self.share * (1 - self.share):.0f} s)"
        return text

    def _write(self, text: str, final: bool = False) -> None:
        if self.tty:
            self.stream.write("\r" + text.ljust(getattr(self, "_width", 0)) + ("\n" if final else ""))
            self._width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def _beat(self) -> None:
        wait = self.after
        while not self._stop.wait(wait):
            self._write(self.line())
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
