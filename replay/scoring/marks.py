"""Rows whose number is not a filter's error (issue 40), marked on every table and never ranked.

* ``still``: every run's position estimate stays at its start (:func:`replay.scoring.scorer.still`):
  a filter given no position input and no velocity it uses; its error is the start's.
* ``reference_input``: the reference is read from a topic the row also takes as input (a bag's
  mapping declaring one topic as the reference and as a fused input or a recorded estimate): the
  row is scored against its own input (the recorded odometry scores exactly 0). Not a filter row whose
  task withholds the scored samples from every filter (``holdout``: every gps_every-th fix fed, scored
  at the others; :mod:`replay.scoring.provenance` states that sharing in the table's header instead).

:func:`reference_inputs` finds the second from a run's frame metadata (the mapping, the roles and
the task's inputs); :func:`marks` gives the phrases the tables print.
"""

from __future__ import annotations
from replay.scoring.provenance import input_topics


def reference_inputs(frame_meta: dict, filter_name: str) -> str:
    """What of a row's input is read from the reference's own topic (a bag whose mapping declares
    one topic as the reference and as a fused input, or as a recorded estimate): the score then
    measures the topic against itself, not an error. '' when nothing is shared, or unknown."""
    topic_of, ref_topics = input_topics(frame_meta)
    if not ref_topics:
        return ""
    if filter_name.startswith("recorded:"):
        src = ((frame_meta.get("estimates") or {}).get(filter_name[len("recorded:") :]) or {}).get("source")
        topic = str(src).rsplit(" (", 1)[0] if src else None
        return f"recorded from {topic}, the reference's topic" if topic in ref_topics else ""
    inputs = frame_meta.get("task_inputs") or {}
    shared = sorted(
        {k: topic_of.get(str(v).split(" ")[0]) for k, v in inputs.items() if k != "reference"}.items(),
    )
    shared = [(k, t) for k, t in shared if t is not None and t in ref_topics]
    if not shared:
        return ""
    return f"{', '.join(k for k, _ in shared)} read from {shared[0][1]}, the reference's topic"


def marks(row) -> list[str]:
    """Why a row's number is not a filter's error, one phrase each (issue 40): its estimate never
    moves (``still``), or its reference is one of its inputs (``reference_input``). Such rows are
    marked on every table and never named the best. Works on rows read back from a CSV too."""
    out = []
    if str(row.get("still")) == "True":
        out.append("never moves: every estimate stays at its start, so its error is the start's, not a filter's")
    if row.get("reference_input"):
        out.append(
            f"reference is an input ({row['reference_input']}): scored against its own input, "
            "not an independent reference"
        )
    return out


def rankable(row) -> bool:
    """Whether a row may be ranked against the others (no :func:`marks`)."""
    return not marks(row)
