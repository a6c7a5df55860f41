"""Export an evaluation (``replay eval`` output directory, or one configuration set and run
of a campaign) as one Foxglove MCAP.

Reads the run with ``replay.outputs.run_data.load_run`` (the manifest, one run of the
estimates, the dataset reloaded and the task problem rebuilt for the reference; no
filter is run again).

Channels (schemas from the ``foxglove-schemas-protobuf`` package; log time =
publish time = the sample's time, ``meta["t0_ns"]`` or ``epoch`` + ``t``):

| topic | schema | what |
|---|---|---|
| ``/replay/<filter>/pose`` | foxglove.PoseInFrame | estimated position (and heading when the task scores one), every step |
| ``/replay/<filter>/path`` | foxglove.PosesInFrame | the whole estimated trajectory, one message at the first time |
| ``/replay/<filter>/fix`` | foxglove.LocationFix | the estimate in WGS 84 (geodetic data only: meta crs + origin) |
| ``/replay/<filter>/error`` | JSON ``{ex, ey[, ez], norm}`` | position error vs the reference (m), scored steps |
| ``/replay/<filter>/tf`` | foxglove.FrameTransform | ``map -> <filter>/base_link`` at every pose |
| ``/replay/<filter>/covariance`` | foxglove.SceneUpdate | the position covariance ellipsoid (sigma scale in the channel metadata) |
| ``/replay/reference/pose``, ``/path``, ``/fix``, ``/tf`` | as above | the reference where valid |
| ``/sensors/<channel>`` | JSON ``{<component>: value}`` | every sensor channel of the frame at its valid samples |
| ``/tf_static`` | foxglove.FrameTransform | identity ``map -> enu``, once at the first time |

Frames (``replay.outputs.foxglove_scene``): ``map`` is the root, the local east-north-up
frame; the pose, path and fix channels keep their frame id ``"enu"``, the same frame
(``/tf_static``); each track's body is ``<track>/base_link``. A north-east-down task's
positions and heading are converted (``run_data.enu_axes``). A recorded estimate
(``recorded:<name>``) is exported as a filter (position only).

Metadata records: ``replay.manifest`` holds the run's manifest as written
(``manifest.json``; for a campaign, ``campaign.toml`` and each selected ``config.json``),
``replay.export`` what was exported (source, run, tracks, sigma scale, frames).

Messages are encoded many at a time (``replay.outputs.pb_columns`` for protobuf,
``json_rows`` for JSON) and written by ``replay.outputs.mcap_bulk.BulkWriter``
(time-ordered zstd chunks) in time windows of about 65,536 messages: the memory
holds one window, not the file (``McapOut``). The file goes to a hidden temporary
name beside the target and is renamed over it when complete
(``replay.outputs.export_safety``).
"""  # noqa: E501 (Markdown tables)

from __future__ import annotations

import json

import numpy as np

from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame

from replay.adapters.geodesy import enu_to_geodetic
from replay.outputs import foxglove_scene as scene
from replay.outputs.export_safety import check_target, export_set, run_inputs
from replay.outputs.foxglove_scene import ROOT, SIGMA, plan_transforms
from replay.outputs.pb_columns import Rows, embed, encode
from replay.util.version import __version__
from replay.util import covcols
from replay.outputs.run_data import enu_axes, enu_yaw, load_run, ned, read_estimates, time_ns, to_enu, track_index
from replay.util.errors import ReplayError
from replay.outputs.mcap_out import McapOut, json_rows

__all__ = [
    "McapOut",
    "export_run",
    "json_rows",
    "load_run",
    "read_estimates",
    "time_ns",
    "write_mcap",
    "write_run_mcap",
]

FRAME_ID = "enu"


# ---------------------------------------------------------------- schemas


# ---------------------------------------------------------------- writing


def _quat_yaw(yaw):
    return np.column_stack([np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2), np.cos(yaw / 2)])


def _yaw_quat(yaw):
    """Quaternions of yaws; a NaN yaw (none estimated) -> identity."""
    y = np.asarray(yaw, float)
    return _quat_yaw(np.where(np.isfinite(y), y, 0.0))


def _stamp(ns) -> dict:
    sec, nanos = np.divmod(np.asarray(ns, np.int64), 1_000_000_000)
    return {"timestamp.seconds": sec, "timestamp.nanos": nanos}


def _pose_fields(pos3, quat, prefix="") -> dict:
    f = {f"{prefix}position.{a}": pos3[:, i] for i, a in enumerate("xyz")}
    f.update({f"{prefix}orientation.{a}": quat[:, i] for i, a in enumerate("xyzw")})
    return f


PATH_BLOCK = 1 << 14  # poses encoded at a time into a path message


def _plan_track(out: McapOut, prefix: str, ns, pos, yaw, ok, geo_meta, body=None) -> None:
    """Pose, path, (geodetic data) fix and (``body``: a frame name) transform channels of one
    track at rows ``ok``.

    ``pos(rows)``, ``yaw(rows)``: ENU positions (n, 3) and yaws (NaN: none) of those
    rows, taken when a window is written (no copy of the whole track is kept).
    """

    idx = np.flatnonzero(ok)
    if not len(idx):
        return
    t = ns[idx]

    def rows(sel):  # ENU positions and yaw quaternions of messages sel
        return pos(idx[sel]), _yaw_quat(yaw(idx[sel]))

    def poses(sel):
        p, q = rows(sel)
        return encode(
            PoseInFrame, {**_stamp(t[sel]), "frame_id": FRAME_ID, **_pose_fields(p, q, "pose.")}, len(sel)
        ).flat()

    def path(_):  # one PosesInFrame whose repeated `poses` field is every pose in turn
        number = PosesInFrame.DESCRIPTOR.fields_by_name["poses"].number
        pieces = [encode(PosesInFrame, {**_stamp(t[:1]), "frame_id": FRAME_ID}, 1).flat()[0]]
        for lo in range(0, len(idx), PATH_BLOCK):
            sel = np.arange(lo, min(lo + PATH_BLOCK, len(idx)))
            items = encode(Pose, _pose_fields(*rows(sel)), len(sel))
            pieces.append(Rows(len(sel), embed(number, items)).flat()[0])
        body = np.concatenate(pieces)
        return body, np.array([len(body)])

    def fixes(sel):

        lat, lon, alt = enu_to_geodetic(rows(sel)[0], geo_meta)
        return encode(
            LocationFix,
            {**_stamp(t[sel]), "frame_id": FRAME_ID, "latitude": lat, "longitude": lon, "altitude": alt},
            len(sel),
        ).flat()

    out.plan(out.proto_channel(f"{prefix}/pose", PoseInFrame), t, poses)
    out.plan(out.proto_channel(f"{prefix}/path", PosesInFrame), t[:1], path, big=True)
    if geo_meta:
        out.plan(out.proto_channel(f"{prefix}/fix", LocationFix), t, fixes)
    if body:
        plan_transforms(out, f"{prefix}/tf", body, ns, pos, lambda rows: _yaw_quat(yaw(rows)), ok)


def _plan_values(out: McapOut, topic, ns, values, ok, names) -> None:
    """A JSON channel: rows ``ok`` of ``values`` (a function of row indices, or an array)."""
    idx = np.flatnonzero(ok)
    if not len(idx):
        return
    get = values if callable(values) else (lambda rows: values.reshape(len(values), -1)[rows])
    out.plan(out.json_channel(topic, names), ns[idx], lambda sel: json_rows(get(idx[sel]), names))


def _error_rows(err):
    """Position error components and their norm, for rows of ``err`` that are all finite."""

    def get(rows):
        e = err[rows]
        return np.column_stack([e, np.sqrt(np.sum(e**2, axis=1))])

    return get


def export_run(run_dir, mcap_path, data_dir=None, run: int = 0, select=None, sigma=None, progress=None) -> int:
    """Write one run of ``run_dir`` (an eval output or a campaign, ``select``: see
    ``run_data.load_run``) as a Foxglove MCAP; returns the number of messages.

    Refused before anything is read or written: a target that is an input of the run
    (or inside one), or an existing file not written by replay (``export_safety``).
    """

    inputs = run_inputs(run_dir, data_dir)
    check_target(mcap_path, inputs, "mcap")
    loaded = load_run(run_dir, data_dir, run=run, select=select)
    check_target(mcap_path, inputs + [loaded["frame"].meta.get("path")], "mcap")
    return write_run_mcap(loaded, mcap_path, sigma=sigma, progress=progress)


def write_run_mcap(run: dict, mcap_path, sigma=None, progress=None) -> int:
    """The MCAP of a loaded run (``run_data.load_run``), with its manifest as metadata."""
    return write_mcap(
        mcap_path,
        run["frame"],
        run["problem"],
        run["estimates"],
        sigma=sigma,
        metadata={"replay.manifest": run.get("manifest", {}), "replay.export": export_info(run, sigma)},
        progress=progress,
    )


def export_info(run: dict, sigma=None) -> dict:
    """The ``replay.export`` metadata: what was exported from where."""

    return {
        "source": str(run.get("source", "")),
        "run": str(run.get("run", 0)),
        "tracks": json.dumps(["reference", *run["estimates"]]),
        "sigma": f"{sigma or SIGMA:g}",
        "frames": json.dumps({"root": ROOT, "poses": FRAME_ID, "body": "<track>/base_link"}),
        "replay_version": __version__,
    }


def write_mcap(
    mcap_path,
    frame,
    problem,
    estimates: dict,
    *,
    compression: str = "zstd",
    chunk_size: int = 4 << 20,
    window: int = 1 << 16,
    sigma=None,
    metadata=None,
    progress=None,
) -> int:
    """Estimates ``{filter: {t, x, P, err}}`` of one run, the reference and the sensors -> MCAP.

    ``sigma``: the scale of the covariance ellipsoids (default ``foxglove_scene.SIGMA``);
    ``metadata``: ``{record name: {key: text}}`` written as MCAP Metadata records;
    ``progress``: a :class:`replay.util.progress.Progress` told of the messages written.
    Written to a hidden temporary file beside ``mcap_path`` and renamed over it when
    complete; an existing ``mcap_path`` is replaced only if replay wrote it.
    """

    sigma = scene.SIGMA if sigma is None else float(sigma)
    if not (np.isfinite(sigma) and sigma > 0):
        raise ReplayError(f"export: --sigma {sigma:g}: the ellipsoid scale must be a positive number")
    geo = frame.meta if frame.meta.get("crs") and frame.meta.get("origin") else None
    ns_frame = time_ns(frame, frame.t)
    axes_enu, is_ned = enu_axes(problem), ned(problem)
    colours = scene.colours(estimates)
    with export_set(mcap_path, "mcap").staged() as tmp:
        out = McapOut(tmp, compression=compression, chunk_size=chunk_size, window=window, name=mcap_path)
        for name, data in (metadata or {}).items():
            out.w.add_metadata(name, data)
        starts = [ns_frame[:1]] + [time_ns(frame, e["t"][:1]) for e in estimates.values()]
        scene.plan_static(out, int(np.concatenate(starts).min()), FRAME_ID)
        ref = np.asarray(problem.truth_position, float)
        ok = problem.truth_valid & np.isfinite(ref).all(axis=1)
        no_yaw = lambda rows: np.full(len(rows), np.nan)  # noqa: E731
        _plan_track(
            out,
            "/replay/reference",
            ns_frame,
            lambda rows: to_enu(ref[rows], axes_enu),
            no_yaw,
            ok,
            geo,
            scene.body_frame("reference"),
        )
        axes = [f"e{a}" for a in problem.axis_names]
        for name, est in estimates.items():
            ns = time_ns(frame, est["t"])
            x = est["x"]
            pidx, hidx = track_index(name, problem)
            yaw = (lambda rows, x=x, h=hidx: enu_yaw(x[rows, h], is_ned)) if hidx is not None else no_yaw
            pos = lambda rows, x=x, p=pidx: to_enu(x[rows][:, p], axes_enu)  # noqa: E731
            finite = np.isfinite(x[:, pidx]).all(axis=1)
            _plan_track(out, f"/replay/{name}", ns, pos, yaw, finite, geo, scene.body_frame(name))
            P = covcols.as_matrices(est["P"])  # (n, nx, nx), taken per window (no copy of the track's)
            cov = lambda rows, P=P, p=pidx: scene.enu_covariance(P[rows][:, p][:, :, p], axes_enu)  # noqa: E731
            has_cov = (
                finite
                & (np.diagonal(P, axis1=1, axis2=2)[:, pidx] >= 0).all(axis=1)
                & np.isfinite(P[:, pidx][:, :, pidx]).all(axis=(1, 2))
            )
            scene.plan_ellipsoids(out, f"/replay/{name}/covariance", name, ns, pos, cov, has_cov, sigma, colours[name])
            _plan_values(
                out,
                f"/replay/{name}/position_covariance",
                ns,
                lambda rows, cov=cov: scene.upper(cov(rows)),
                has_cov,
                scene.UPPER_NAMES,
            )
            err = est["err"][:, : len(axes_enu)]
            _plan_values(
                out, f"/replay/{name}/error", ns, _error_rows(err), np.isfinite(err).all(axis=1), axes + ["norm"]
            )
        for cname, ch in frame.channels.items():
            comps = list(ch.components) or ([cname] if ch.width == 1 else [f"c{i}" for i in range(ch.width)])
            _plan_values(out, f"/sensors/{cname}", ns_frame, ch.values, ch.valid, comps)
        return out.close(progress)
