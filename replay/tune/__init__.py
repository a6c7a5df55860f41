"""``replay tune``: each filter at its best on training data, scored on held-out data.

* :mod:`.space` — the search space (``log[a,b]``, ``[a,b]``, choices), checked against the
  declarations before any trial;
* :mod:`.objectives` — what a trial minimises, from the stored unit records;
* :mod:`.grid` — a declared grid's points and the rule picking one (lowest RMSE, then ANEES among near ties);
* :mod:`replay.scoring.likelihood` — the innovations' negative log-likelihood (Kalman family, linear models);
* :mod:`.study` — the Optuna study (seeded TPE, SQLite ``DIR/study.db``, resumable);
* :mod:`.run` — trials as campaign units, the held-out scoring, the leaderboard and ``tuned.toml``.
"""
