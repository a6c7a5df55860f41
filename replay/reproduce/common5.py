"""Helpers shared by the reproductions of papers 001 and 003 (Monte Carlo tables, plots)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from replay.score import ci95


def mean_ci(values) -> str:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return f"{v.mean():.3f} ± {ci95(v):.3f}" if len(v) else "n/a"


def rmse_curve(err: np.ndarray) -> np.ndarray:
    """RMSE across runs at each step of errors (runs, n): sqrt(mean_runs e²), NaN-aware."""
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.nanmean(err**2, axis=0))


def plot_curves(path: Path, t, curves: dict, panels: list[str], ylabel: str, title: str) -> None:
    """One panel per name in ``panels``; ``curves[filter][panel]`` is an (n,) RMSE curve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 2.2 * len(panels)), sharex=True)
    for ax, name in zip(np.atleast_1d(axes), panels):
        for flt, c in curves.items():
            ax.plot(t, c[name], label=flt, lw=1)
        ax.set_ylabel(f"{name} {ylabel}")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].legend()
    np.atleast_1d(axes)[0].set_title(title)
    np.atleast_1d(axes)[-1].set_xlabel("t (s)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
