"""Memory a run will need, predicted before it starts and refused in one line when it cannot fit.

Two predictable needs (the rest is reported as "out of memory" if it happens,
:mod:`replay.run.failures`):

* a particle filter holds ``n_particles x runs computed at once x state size x 8 bytes``
  (:func:`check_particles`; campaigns may call it for a unit's block too);
* ``replay eval`` keeps every run's estimates, covariances and errors in memory
  (:func:`check_kept`): about ``filters x runs x steps x (nx² + 3 nx + 24) x 8`` bytes.

Available memory: psutil's ``available`` when installed, else ``MemAvailable`` of
``/proc/meminfo``, else ``os.sysconf``; lowered to the address-space limit (``ulimit -v``).
Unknown: nothing is refused.
"""

from __future__ import annotations

import os

from replay.util.errors import ReplayError


def available_memory() -> int | None:
    """Bytes this process may still allocate (see the module docstring), or None when unknown."""
    avail = None
    try:
        # lazy: optional, psutil is not a dependency (the kernel's figures otherwise)
        import psutil  # noqa: PLC0415

        avail = int(psutil.virtual_memory().available)
    except Exception:  # noqa: BLE001 — psutil absent or unusable: the kernel's own figures
        try:
            with open("/proc/meminfo") as fh:
                avail = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("MemAvailable:"))
        except (OSError, StopIteration, ValueError, IndexError):
            try:
                avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
            except (ValueError, OSError, AttributeError):
                avail = None
    try:
        # lazy: POSIX only (no resource module on Windows)
        import resource  # noqa: PLC0415

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY and soft > 0:
            avail = soft if avail is None else min(avail, soft)
    except (ImportError, OSError, ValueError):
        pass
    return avail


def size(n: float) -> str:
    """Bytes in words: ``1.2 TB``."""
    for unit in ("bytes", "kB", "MB", "GB", "TB", "PB"):
        if n < 1000 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000
    return ""  # pragma: no cover


def check_particles(name: str, params: dict, at_once: int, nx: int, avail: int | None = None) -> None:
    """Refuse (one line naming ``-p NAME.n_particles``) particles that cannot fit in memory."""
    n = params.get("n_particles")
    avail = available_memory() if avail is None else avail
    if not isinstance(n, int) or avail is None:
        return
    need = n * at_once * nx * 8
    if need > avail:
        raise ReplayError(
            f"-p {name}.n_particles = {n}: the particles need about {size(need)} of memory "
            f"({n} particles x {at_once} runs at once x {nx} state components x 8 bytes); "
            f"{size(avail)} available: use fewer particles"
        )


def check_kept(filters: int, runs: int, steps: int, nx: int, avail: int | None = None) -> None:
    """Refuse (one line naming ``runs``) an evaluation whose kept estimates cannot fit in memory."""
    avail = available_memory() if avail is None else avail
    if avail is None:
        return
    need = filters * runs * steps * (nx * nx + 3 * nx + 24) * 8
    if need > avail:
        raise ReplayError(
            f"runs = {runs}: replay eval keeps every run's estimates in memory, about {size(need)} "
            f"({filters} filter(s) x {runs} runs x {steps} steps of a {nx}-component state); "
            f"{size(avail)} available: use fewer runs, or a campaign (it stores runs on disk)"
        )
