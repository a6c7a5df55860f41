"""One run of an evaluation directory (or of a campaign's configurations) exported as a Foxglove MCAP
and/or a ROS 2 bag: ``replay export`` and ``replay eval --mcap/--ros2-bag``.

Both targets are checked before the run is loaded (once, for both exports) and again against the
dataset file the load resolved (:func:`replay.outputs.export_safety.check_exports`); each is then
written through its :class:`replay.util.output_set.OutputSet` (a hidden temporary beside it, moved
into place when complete).
"""

from __future__ import annotations

from replay.outputs.export_mcap import write_run_mcap
from replay.outputs.export_ros2 import write_run_ros2
from replay.outputs.export_safety import check_exports, run_inputs
from replay.outputs.run_data import load_run

LABELS = {"mcap": "export mcap", "ros2": "export ros2 bag"}  # the progress displays' labels


def export_run(run_dir, mcap_out=None, ros2_out=None, *, data_dir=None, run=0, select=None, sigma=None, progress=None):
    """Export run ``run`` of ``run_dir`` (``select``: a campaign's configurations, see
    :func:`replay.outputs.run_data.load_run`); yields, after each export, ``{"target", "kind",
    "messages", "run", "tracks"}``. ``progress(kind)``: a progress display for the messages of an
    export ("mcap" or "ros2"; closed when it is written), or None."""
    inputs = run_inputs(run_dir, data_dir)
    check_exports(mcap_out, ros2_out, inputs)
    loaded = load_run(run_dir, data_dir, run=run, select=select)
    check_exports(mcap_out, ros2_out, inputs + [loaded["frame"].meta.get("path")])
    for target, kind, write in (
        (mcap_out, "mcap", lambda p: write_run_mcap(loaded, mcap_out, sigma=sigma, progress=p)),
        (ros2_out, "ros2", lambda p: write_run_ros2(loaded, ros2_out, progress=p)),
    ):
        if not target:
            continue
        shown = progress(kind) if progress else None
        try:
            n = write(shown)
        finally:
            if shown is not None:
                shown.close()
        yield {"target": target, "kind": kind, "messages": n, "run": loaded["run"], "tracks": list(loaded["estimates"])}
