"""The swarm particle filters of paper 002 by name: IGWO-STCPF, GWO-PF, IGWO-PF, PSO-PF, PSO-CPF (one
engine: :mod:`replay.filters.p002.igwo_stcpf`)."""

from __future__ import annotations

from replay.filters.case import Case
from replay.filters.p002.igwo_stcpf import (
    GWO_NAMES,
    PROPOSAL_NAMES,
    PSO_NAMES,
    STCKF_NAMES,
    SwarmParticleFilter,
)
from replay.util.params import without


class IGWOSTCPF(SwarmParticleFilter):
    """IGWO-STCPF (002, §3.3): STCKF importance density, IGWO in place of resampling."""

    name, proposal, optimizer = "igwo-stcpf", "stckf", "igwo"
    CASE = Case(params={"n_particles": 12, "t_max": 3})
    PARAMS = without(SwarmParticleFilter.PARAMS, "proposal", "optimizer", *PSO_NAMES)


class GWOPF(SwarmParticleFilter):
    """Bootstrap PF with standard GWO in place of resampling (002, §3.2 benchmark 1)."""

    name, proposal, optimizer = "gwo-pf", "prior", "gwo"
    CASE = Case("sim/ungm", "ungm", {"n_particles": 30, "t_max": 3}, first=30)
    PARAMS = without(SwarmParticleFilter.PARAMS, "proposal", "optimizer", *PSO_NAMES, *PROPOSAL_NAMES)


class IGWOPF(GWOPF):
    """Bootstrap PF with IGWO in place of resampling (002, §3.2 benchmark 1)."""

    name, proposal, optimizer = "igwo-pf", "prior", "igwo"
    CASE = Case("sim/ungm", "ungm", {"n_particles": 30, "t_max": 4}, first=30)


class PSOPF(SwarmParticleFilter):
    """PSO-PF baseline (002, §4.1): bootstrap PF, PSO (20 iterations, bounded) in place of resampling.

    The PSO iteration count is ``t_max`` (the paper's "iterations"; one name for
    every swarm filter). Nothing is compiled (the bootstrap proposal and PSO are numpy): it runs
    on any model, kernels or not, with the model's own likelihood.
    """

    name, proposal, optimizer = "pso-pf", "prior", "pso"
    CASE = Case(params={"n_particles": 20, "t_max": 3})
    PARAMS = without(SwarmParticleFilter.PARAMS, "proposal", "optimizer", *GWO_NAMES, *PROPOSAL_NAMES)


class PSOCPF(SwarmParticleFilter):
    """PSO-CPF baseline (002, §4.1): PSO-PF with a per-particle CKF importance density (``t_max`` iterations)."""

    name, proposal, optimizer = "pso-cpf", "ckf", "pso"
    CASE = Case(params={"n_particles": 12, "t_max": 3})
    PARAMS = without(SwarmParticleFilter.PARAMS, "proposal", "optimizer", *GWO_NAMES, *STCKF_NAMES)
