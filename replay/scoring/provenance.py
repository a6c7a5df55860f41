"""Where a run's reference comes from (issue 35 item 1): one record per evaluation, in the manifest
(``dataset.reference``) and printed in the header of every table of the run.

The record is plain JSON, so that any reference source can fill it::

    {"kind": "onboard solution", "source": "...", "independent": false,
     "shares": "gps_position.position: ...", "compared": "..."}

``kind`` is one of :data:`KINDS`. A reference source states its own provenance in its frame's
``meta["reference_provenance"]`` — ``{"kind", "source", "built_from": {channel: how}}``, e.g. the Bohai
adapter (the vehicle's navigation solution, built from its GPS on the surface), or a smoothed track
built from the recording's sensors. Otherwise it is found: a simulated dataset's truth; a bag
mapping's ``[reference]`` topic that is also a fed channel's topic (a fed sensor); any other
recorded reference (its independence is not declared). ``shares`` names the task's fed inputs that
share a source with the reference; when it is non-empty ``independent`` is false and ``compared``
says what the table then measures — the raw-measurement flag is replaced by that statement
(:func:`replay.scoring.summary.against_measurements`).
"""

from __future__ import annotations

KINDS = {
    "simulated truth": "the simulator's true state",
    "ground truth": "an external reference independent of the inputs",
    "onboard solution": "the vehicle's own navigation solution",
    "fed sensor": "a sensor the filters are also fed",
    "smoothed track": "a track smoothed from the recording's own sensors",
    "recorded reference": "a reference of the recording whose independence is not declared",
}


def input_topics(frame_meta: dict) -> tuple[dict, set]:
    """({channel: topic} of a bag mapping's channels, {the reference's topics}); empty without a mapping."""
    mapping = frame_meta.get("mapping")
    if not isinstance(mapping, dict):
        return {}, set()
    entries = [e for e in mapping.get("entries", []) if isinstance(e, dict)]
    topic_of = {e.get("name"): e.get("topic") for e in entries}
    for items in (frame_meta.get("roles") or {}).values():  # channels of a role -> their entry
        for item in items if isinstance(items, list) else []:
            topic_of.update({ch: topic_of.get(item.get("entry")) for ch in (item.get("channels") or {}).values()})
    return topic_of, {e.get("topic") for e in entries if e.get("reference")}


def fed_channels(inputs: dict) -> dict:
    """{task input: the frame channel it reads} (``Problem.inputs``: ``"channel (description)"``)."""
    return {k: str(v).split(" ")[0] for k, v in (inputs or {}).items() if k not in ("reference", "z0")}


def provenance(
    frame_meta: dict,
    inputs: dict,
    task_params: dict,
    *,
    simulated: bool,
    synthetic: bool,
    declared=None,
    unconstrained=(),
) -> dict:
    """The reference's provenance record for a run (module docstring); ``declared``: a task's own record,
    when the task scores against something else than the frame's reference (the same form as the frame's
    ``meta["reference_provenance"]``, which it replaces; its ``compared`` replaces the default statement);
    ``unconstrained``: the task's lines on state it fuses nothing to fix (``Problem.unconstrained``: an
    attitude angle no input measures, :mod:`replay.tasks.fusion_heading`), what a distance to the
    reference then means; kept as the record's ``unconstrained`` and printed under it."""
    fed = fed_channels(inputs)
    declared = declared or frame_meta.get("reference_provenance")
    ref_desc = str((inputs or {}).get("reference", "the recording's reference"))
    shares, every = {}, None
    if simulated:
        kind, source = "simulated truth", "the simulator's true state"
    elif isinstance(declared, dict) and declared.get("kind") in KINDS:
        kind, source = declared["kind"], str(declared.get("source", ""))
        built = declared.get("built_from") or {}
        shares = {k: str(built[ch]) for k, ch in fed.items() if ch in built}
    else:
        topic_of, ref_topics = input_topics(frame_meta)
        topic = sorted(t for t in ref_topics if t)[:1]
        source = f"topic {topic[0]}" if topic else ref_desc
        every = (task_params or {}).get("gps_every") if (task_params or {}).get("holdout") else None
        for k, ch in fed.items():
            if topic_of.get(ch) in ref_topics:
                how = f"the same topic {topic_of[ch]}"
                if every:
                    how += f": every {every}th fix is fed, the others are withheld and scored"
                shares[k] = how
        kind = "fed sensor" if shares else "recorded reference"
    out = {
        "kind": kind,
        "source": source,
        "independent": not shares,
        "shares": "; ".join(f"{k} ({how})" for k, how in sorted(shares.items())),
    }
    if shares and every:
        out["compared"] = (
            "each filter and the measurements row (the last fed fix held) are scored at the fixes withheld "
            "from every filter, against the same sensor: an error is the distance to that sensor's other "
            "fixes, and a filter behind the held fix measures how the sensor's errors are correlated in "
            "time, not whether fusion hurts"
        )
    elif shares and isinstance(declared, dict) and declared.get("compared"):
        out["compared"] = str(declared["compared"])
    elif shares:
        out["compared"] = (
            "an error is the distance to a solution built from a fed input, not to the truth: where that "
            "input is fed it is scored against itself, elsewhere against the vehicle's own estimate; a "
            "filter behind the raw measurements is not evidence that fusion hurts"
        )
    elif synthetic:
        out["compared"] = (
            "the measurements are the reference plus the task's own noise: the table measures how well each "
            "filter removes that noise"
        )
    if unconstrained:
        out["unconstrained"] = [str(line) for line in unconstrained]
    return out


def header(record: dict | None) -> list[str]:
    """The lines a table prints about its reference (none when the run recorded no provenance)."""
    if not record:
        return []
    lines = [f"reference: {record['kind']} ({record.get('source') or KINDS.get(record['kind'], '')})"]
    if record.get("shares"):
        lines.append(f"reference shares a source with a fed input: {record['shares']}")
        lines.append(f"what is compared: {record['compared']}")
    elif record.get("kind") == "recorded reference":
        lines[0] += "; its independence of the inputs is not declared"
    return lines + list(record.get("unconstrained") or ())
