"""Filters. ``FILTERS`` maps a filter name (as on the command line) to "module:Class".

Every filter runs on the model protocol of :mod:`replay.model` and knows
nothing of files, datasets or the CLI.
"""
FILTERS = {
    "kf": "replay.filters.kalman:KalmanFilter",
    "ekf": "replay.filters.kalman:EKF",
    "ukf": "replay.filters.sigma:UKF",
    "ckf": "replay.filters.sigma:CKF",
    "pf": "replay.filters.pf:ParticleFilter",
    "gpf": "replay.filters.gpf:GreyParticleFilter",
    "mmpf": "replay.filters.mmpf:MultipleModelPF",
    "stckf": "replay.filters.stckf:STCKF",
    "stcpf": "replay.filters.stcpf:CubatureParticleFilter",
    "igwo-stcpf": "replay.filters.igwo_stcpf:IGWOSTCPF",
    "gwo-pf": "replay.filters.igwo_stcpf:GWOPF",
    "igwo-pf": "replay.filters.igwo_stcpf:IGWOPF",
    "pso-pf": "replay.filters.igwo_stcpf:PSOPF",
    "pso-cpf": "replay.filters.igwo_stcpf:PSOCPF",
    "aukf": "replay.filters.aukf:AUKF",
    "wf-pf": "replay.filters.wfpf:WeightFactorPF",
}


def make_filter(name: str, **params):
    """Instantiate the filter registered as ``name`` with ``params``."""
    from replay.util.lookup import instantiate

    return instantiate(FILTERS, name, "filter", **params)
