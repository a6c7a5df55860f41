"""Evaluation campaigns: many datasets x tasks x filters x parameters x runs, resumable.

``spec`` reads and checks campaign files, ``units`` computes a block of runs,
``store`` keeps finished units on disk atomically and checks them when read
(``encode``: a unit's per-step table as Parquet bytes, encoded in the workers),
``lock`` keeps one campaign process per result directory, ``execute`` runs the
missing (or damaged) units on a backend (in-process, local processes, Dask),
``board`` writes the leaderboard and paired comparisons, ``progress`` reports as
units finish.
"""
