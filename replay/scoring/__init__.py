"""Scoring statistics shared by the library: :mod:`replay.scoring.significance` (tests, intervals, multiplicity)."""
