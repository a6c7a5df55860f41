"""Deprecated alias, to be deleted when its last callers are gone: every filter runs over the
Monte Carlo run axis through :meth:`replay.filters.base.Filter.run_batch` (no algorithm here)."""
from __future__ import annotations


def run_batched(flt, model, Z, X0, P0, rngs):
    """``flt.run_batch(model, Z, X0, P0, rngs)``."""
    return flt.run_batch(model, Z, X0, P0, rngs)


def supports(flt) -> bool:
    """Every filter runs batched."""
    return True


def exact(flt) -> bool:
    """Every filter's batched runs equal its one-by-one runs."""
    return True
