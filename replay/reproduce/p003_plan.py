"""The evaluations of the paper-003 reproduction (:mod:`.p003`): settings and the job list."""
from __future__ import annotations

import numpy as np

from .common5 import Job

DS = "sim/uav-formation"
DEG = np.pi / 180
SIGMA1 = 0.4 * DEG  # 003 §4.1
N_PRINTED = 1000
N_SWEEP = (50, 100, 200, 500)
N_BASE = 100  # particles of the regime sweeps (process noise, contrast, mismatch)
ACCEL = (0.03, 0.1, 0.3)  # process noise sigma_a (m/s^2); 1.0 (ours) is the N sweep's row
CONTRAST = ((5, 0.05), (5, 0.3), (10, 0.05), (10, 0.1), (10, 0.3))  # (sigma2/sigma1, eps)
MISMATCH = ((5, 0.3), (10, 0.1))
LIKELIHOODS = (("core", 0.0), ("glint", 1.0))  # task eps: the Gaussian the filter assumes
WIDE = ((10, 0.1),)  # the settings where the filter also assumes the wide (glint) Gaussian
ROUGHENING = 0.2


def glint(ratio, eps):
    return {"sigma2": ratio * SIGMA1, "eps": eps}


def wf(n, alpha, **extra):
    return {"n_particles": n, "alpha": alpha, **extra}


def likelihoods(ratio, eps):
    """The mismatched Gaussians of a setting: the core always, the wide one where :data:`WIDE` says."""
    return [(lik, e) for lik, e in LIKELIHOODS if lik == "core" or (ratio, eps) in WIDE]


def plan() -> list[Job]:
    """Every evaluation of the document, in order (keys are read by :mod:`.p003_doc`)."""
    N = N_PRINTED
    jobs = [Job("printed", DS, ("pf", "wf-pf", "ukf", "ekf"),
                filter_params={"pf": {"n_particles": N}, "wf-pf": wf(N, 0.75)}),
            Job("printed a=1", DS, ("wf-pf",), filter_params={"wf-pf": wf(N, 1.0)}),
            Job("printed rough", DS, ("pf",), filter_params={"pf": {"n_particles": N, "roughening": ROUGHENING}})]
    jobs += [Job(f"printed a={a}", DS, ("wf-pf",), filter_params={"wf-pf": wf(N, a)}) for a in (0.5, 0.25)]
    for n in N_SWEEP:
        jobs += [Job(f"N={n}", DS, ("pf", "wf-pf"), filter_params={"pf": {"n_particles": n}, "wf-pf": wf(n, 0.75)}),
                 Job(f"N={n} a=0.5", DS, ("wf-pf",), filter_params={"wf-pf": wf(n, 0.5)}),
                 Job(f"N={n} a=1", DS, ("wf-pf",), filter_params={"wf-pf": wf(n, 1.0)})]
    for s in ACCEL:
        d = {"accel_sigma": s}
        jobs += [Job(f"accel={s}", DS, ("pf", "wf-pf"), d,
                     {"pf": {"n_particles": N_BASE}, "wf-pf": wf(N_BASE, 0.75)}),
                 Job(f"accel={s} a=0.5", DS, ("wf-pf",), d, {"wf-pf": wf(N_BASE, 0.5)}),
                 Job(f"accel={s} a=1", DS, ("wf-pf",), d, {"wf-pf": wf(N_BASE, 1.0)}),
                 Job(f"accel={s} rough", DS, ("pf",), d, {"pf": {"n_particles": N_BASE, "roughening": ROUGHENING}})]
    jobs.append(Job("accel=1.0 rough", DS, ("pf",), {},
                    {"pf": {"n_particles": N_BASE, "roughening": ROUGHENING}}))
    for ratio, eps in CONTRAST:
        d = glint(ratio, eps)
        jobs += [Job(f"contrast {ratio} eps={eps}", DS, ("pf", "wf-pf", "ukf"), d,
                     {"pf": {"n_particles": N_BASE}, "wf-pf": wf(N_BASE, 0.75)}),
                 Job(f"contrast {ratio} eps={eps} a=0.5", DS, ("wf-pf",), d, {"wf-pf": wf(N_BASE, 0.5)}),
                 Job(f"contrast {ratio} eps={eps} a=1", DS, ("wf-pf",), d, {"wf-pf": wf(N_BASE, 1.0)})]
    for ratio, eps in MISMATCH:
        d = glint(ratio, eps)
        for lik, task_eps in likelihoods(ratio, eps):
            t = {"eps": task_eps}
            k = f"mismatch {ratio} eps={eps} {lik}"
            jobs += [Job(k, DS, ("pf", "wf-pf"), d, {"pf": {"n_particles": N_BASE}, "wf-pf": wf(N_BASE, 0.75)}, t)]
            jobs += [Job(f"{k} a={a}", DS, ("wf-pf",), d, {"wf-pf": wf(N_BASE, a)}, t)
                     for a in ((0.5, 0.25, 1) if lik == "core" else (0.5, 1))]
            if lik == "core":
                jobs.append(Job(f"{k} a=0.5 nofloor", DS, ("wf-pf",), d,
                                {"wf-pf": wf(N_BASE, 0.5, weight_floor=1e-300)}, t))
    return jobs
