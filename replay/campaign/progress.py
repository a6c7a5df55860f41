"""Progress of a campaign: a live bar on a terminal, plain periodic lines otherwise, nothing with -q."""
from __future__ import annotations

import sys
import time


class Progress:
    """Counts units done; ``update(n)`` after each finished job."""

    def __init__(self, total: int, quiet: bool = False, stream=None, every: float = 10.0):
        self.total, self.quiet, self.every = total, quiet, every
        self.stream = stream or sys.stderr
        self.done = self.failed = 0
        self.t0 = self.last = time.monotonic()
        self.bar = None
        if not quiet and total and getattr(self.stream, "isatty", lambda: False)():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="unit", file=self.stream, dynamic_ncols=True,
                            desc="campaign", smoothing=0.1)

    def update(self, n: int, failed: int = 0) -> None:
        self.done += n
        self.failed += failed
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.update(n)
            if failed:
                self.bar.set_postfix(failed=self.failed)
            return
        now = time.monotonic()
        if now - self.last >= self.every or self.done >= self.total:
            self.last = now
            self.stream.write(self.line(now) + "\n")
            self.stream.flush()

    def line(self, now=None) -> str:
        el = (now or time.monotonic()) - self.t0
        rate = self.done / el if el > 0 else float("nan")
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        pct = 100.0 * self.done / self.total if self.total else 100.0
        fail = f", {self.failed} failed" if self.failed else ""
        return (f"campaign: {self.done}/{self.total} units ({pct:.0f} %){fail}, "
                f"{rate:.2f} units/s, elapsed {el:.0f} s, ETA {eta:.0f} s")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
