"""Paper p002's algorithms (see ../shared/seeds/README.md and docs/architecture.md).

* :mod:`.stckf` — the strong-tracking CKF (per run) and its fading factor;
* :mod:`.stcpf` — the STCPF / CPF / bootstrap filter class and its engine over
  M runs x N particles; :mod:`.cubature` — the engine's per-particle cubature
  importance density, draw and weight; :mod:`.stack` — stacked small-matrix helpers;
* :mod:`.gwo`, :mod:`.pso` — the optimisers; :mod:`.igwo_stcpf` — the swarm
  filters (IGWO-STCPF, GWO-PF, IGWO-PF, PSO-PF, PSO-CPF);
* :mod:`.compiled` (template bound to a model's kernels by :mod:`.binding`) and
  :mod:`.compiled_util` (model-free helpers) — the numba kernels;
  :mod:`.parallel` — calling them, threads.
"""
