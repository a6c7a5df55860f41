"""Scoring estimates against the reference: errors, alignment, metrics, leaderboard rows, and the
statistics the reproductions decide with (:mod:`replay.scoring.significance`: tests, intervals, multiplicity)."""
