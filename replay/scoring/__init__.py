"""Scoring estimates against the reference: errors, alignment, metrics, leaderboard rows."""
