"""Filters. ``FILTERS`` maps a filter name (as on the command line) to "module:Class".

Every filter runs on the model protocol of :mod:`replay.model` and knows
nothing of files, datasets or the CLI.

``FILTERS`` is a :class:`replay.util.plugins.Registry`: the built-in filters below,
filters registered in this session (``FILTERS.register``), the ``replay.filters``
entry points of installed distributions, and any ``"module:Class"`` name. A plugin
filter is a subclass of :class:`replay.filters.base.Filter` implementing ``engine``
or the per-run ``predict``/``update``, with valid ``PARAMS`` (``docs/plugins.md``).
"""

from replay.util.params import Param  # for plugins: from replay.filters import Filter, Param
from replay.util.plugins import Registry, class_problem
from replay.util.lookup import instantiate

PROTOCOL = ("Estimates", "Filter", "State")  # replay.filters.base, importable from here (plugins)
__all__ = ["FILTERS", "Param", "make_filter", *PROTOCOL]


def __getattr__(name):
    if name in PROTOCOL:
        # lazy: start-up, plugins import this package: replay.filters.base pulls numba and scipy (measured ~1 s)
        from replay.filters import base  # noqa: PLC0415

        return getattr(base, name)
    raise AttributeError(f"module 'replay.filters' has no attribute {name!r}")


def _check(obj):
    """What keeps ``obj`` from being a filter, or None."""
    # lazy: start-up, plugins import this package: replay.filters.base pulls numba and scipy (measured ~1 s)
    from replay.filters.base import Filter  # noqa: PLC0415

    return class_problem(obj, Filter, "replay.filters.base.Filter", (("engine",), ("predict", "update")))


FILTERS = Registry(
    "filter",
    {
        "kf": "replay.filters.kalman:KalmanFilter",
        "ekf": "replay.filters.kalman:EKF",
        "ukf": "replay.filters.sigma:UKF",
        "ckf": "replay.filters.sigma:CKF",
        "kf+rts": "replay.filters.smoothers:KFRTS",
        "ekf+rts": "replay.filters.smoothers:EKFRTS",
        "ukf+rts": "replay.filters.smoothers:UKFRTS",
        "ckf+rts": "replay.filters.smoothers:CKFRTS",
        "pf": "replay.filters.pf:ParticleFilter",
        "pf+ffbsi": "replay.filters.ffbsi:FFBSi",
        "gpf": "replay.filters.p000.gpf:GreyParticleFilter",
        "mmpf": "replay.filters.p000.mmpf:MultipleModelPF",
        "stckf": "replay.filters.p002.stckf:STCKF",
        "stcpf": "replay.filters.p002.stcpf:CubatureParticleFilter",
        "igwo-stcpf": "replay.filters.p002.swarm_filters:IGWOSTCPF",
        "gwo-pf": "replay.filters.p002.swarm_filters:GWOPF",
        "igwo-pf": "replay.filters.p002.swarm_filters:IGWOPF",
        "pso-pf": "replay.filters.p002.swarm_filters:PSOPF",
        "pso-cpf": "replay.filters.p002.swarm_filters:PSOCPF",
        "aukf": "replay.filters.p001.aukf:AUKF",
        "wf-pf": "replay.filters.p003.wfpf:WeightFactorPF",
        "measurements": "replay.filters.measurements:Measurements",
        "gtsam-batch": "replay.filters.factor_graph:GtsamBatch",
        "gtsam-lag": "replay.filters.fixed_lag:GtsamLag",
    },
    check=_check,
)


def make_filter(name: str, **params):
    """Instantiate the filter registered as ``name`` with ``params``."""
    return instantiate(FILTERS, name, "filter", **params)
