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
    "gpf": "replay.filters.p000.gpf:GreyParticleFilter",
    "mmpf": "replay.filters.p000.mmpf:MultipleModelPF",
    "stckf": "replay.filters.p002.stckf:STCKF",
    "stcpf": "replay.filters.p002.stcpf:CubatureParticleFilter",
    "igwo-stcpf": "replay.filters.p002.igwo_stcpf:IGWOSTCPF",
    "gwo-pf": "replay.filters.p002.igwo_stcpf:GWOPF",
    "igwo-pf": "replay.filters.p002.igwo_stcpf:IGWOPF",
    "pso-pf": "replay.filters.p002.igwo_stcpf:PSOPF",
    "pso-cpf": "replay.filters.p002.igwo_stcpf:PSOCPF",
    "aukf": "replay.filters.p001.aukf:AUKF",
    "wf-pf": "replay.filters.p003.wfpf:WeightFactorPF",
}


def make_filter(name: str, **params):
    """Instantiate the filter registered as ``name`` with ``params``."""
    from replay.util.lookup import instantiate

    return instantiate(FILTERS, name, "filter", **params)
