"""Paper p002's algorithms (see ../shared/seeds/README.md and docs/architecture.md).

* :mod:`.stckf` — the strong-tracking CKF (per run) and its fading factor;
* :mod:`.stcpf` — the STCPF / CPF / bootstrap filter class and its engine over
  M runs x N particles; :mod:`.igwo_stcpf` — the swarm filters (IGWO-STCPF,
  GWO-PF, IGWO-PF, PSO-PF, PSO-CPF);
* :mod:`.compiled` (template bound to a model's kernels by :func:`.stcpf.bound_kernels`,
  through :mod:`replay.filters.compiled`, which also calls them and runs threads) and
  :mod:`.compiled_util` (model-free helpers) — the numba kernels, the only
  implementation of the per-particle cubature step, the importance draw and
  weight, and the GWO/IGWO move;
* :mod:`.gwo` — the GWO/IGWO convergence-factor schedule and the uniforms the
  kernels are given; :mod:`.pso` — PSO (numpy, its only implementation);
  :mod:`.stack` — angle helpers of the numpy code.

The former numpy engine is kept only as the test oracle ``tests/oracle_p002.py``
(``tests/test_compiled.py`` compares the kernels with it).
"""
