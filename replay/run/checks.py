"""What ``replay eval`` refuses before any run: the whole configuration before any data is read
(:func:`check_config`), filter names and parameters, recorded estimates the mapping does not declare,
memory that cannot be had."""

from __future__ import annotations

from dataclasses import dataclass

from replay.data import dataset_ref, registry
from replay.filters import make_filter
from replay.run.pipeline import build_problem, load_frame
from replay.trajectory.recorded import RECORDED, is_recorded
from replay.util.errors import ReplayError, shown
from replay.run.resources import available_memory, check_kept, check_particles
from replay.adapters.bags import resolve_mapping
from replay.tasks import make_task
from replay.util.lookup import params_of


def check_filters(filters, filter_params, recorded) -> tuple[list, dict]:
    """``filters`` (names), ``filter_params`` ({name: {parameter: value}}) and ``recorded`` checked: one line."""
    if (
        isinstance(filters, str)
        or not isinstance(filters, (list, tuple))
        or not all(isinstance(f, str) and f.strip() for f in filters)
    ):
        raise ReplayError(f"filters must be a list of filter names (got {filters!r:.80})")
    if filter_params is not None and not (
        isinstance(filter_params, dict)
        and all(isinstance(k, str) and isinstance(v, dict) for k, v in filter_params.items())
    ):
        raise ReplayError(
            f"filter_params must be an object {{filter: {{parameter: value}}}} (got {filter_params!r:.80})"
        )
    if recorded is not None and (
        isinstance(recorded, str)
        or not isinstance(recorded, (list, tuple))
        or not all(isinstance(r, str) for r in recorded)
    ):
        raise ReplayError(f"recorded must be a list of recorded estimate names or null (got {recorded!r:.80})")
    return list(filters), filter_params or {}


def check_memory(configs: list, runs: int, batch: int, data_dir) -> dict | None:
    """Before any work: refuse particles or kept runs that cannot fit in memory (:mod:`replay.run.resources`),
    sized on run 0's problem of the first configuration, which is returned ({0: problem}: not built twice)."""
    offline = [c for c in configs if not is_recorded(c.filter)]
    if not offline or (avail := available_memory()) is None:
        return
    p = build_problem(offline[0], 0, data_dir)
    for c in offline:
        check_particles(c.filter, c.filter_params, min(runs, batch), p.model.nx, avail)
    check_kept(len(offline), runs, len(p.z), p.model.nx, avail)
    return {0: p} if offline[0] is configs[0] else None


def check_recorded(dataset, names, dataset_params) -> None:
    """Refuse, before any recording is read, a ``recorded:<name>`` of ``names`` that the mapping given
    in ``dataset_params`` does not declare in its ``[estimates]`` (without a mapping, the proposed one is
    known only from the recording: :func:`_recorded` checks after reading it)."""
    wanted = [n[len(RECORDED) :] for n in names if is_recorded(n)]
    mapping = (dataset_params or {}).get("mapping")
    if not wanted or mapping is None:
        return

    declared = [e.name for e in resolve_mapping(mapping).estimates]
    unknown = [n for n in wanted if n not in declared]
    if unknown:
        raise ReplayError(
            f"{dataset}: no recorded estimate {unknown[0]!r} (the mapping's [estimates] "
            f"declare: {', '.join(declared) or 'none'})"
        )


def recorded_rows(ref, filters, recorded, seed, first, dataset_params, adapter, data_dir):
    """(``recorded:<name>`` rows to compute, {name: RecordedEstimate}) from the frame's estimates."""
    named = [n for n in filters if is_recorded(n)] + [n if is_recorded(n) else RECORDED + n for n in recorded or ()]
    if not named and (recorded is not None or ref.is_sim):
        return [], {}
    dataset = ref.id
    cfg = {"dataset": dataset, "dataset_params": dataset_params, "first": first, "seed": seed, "adapter": adapter}
    estimates = getattr(load_frame(cfg, 0, data_dir, ds=ref.entry), "estimates", {})
    if recorded is None:
        named += [RECORDED + k for k in estimates if RECORDED + k not in named]
    for n in named:
        if n[len(RECORDED) :] not in estimates:
            raise ReplayError(
                f"{dataset}: no recorded estimate {n[len(RECORDED) :]!r} (the mapping's [estimates] "
                f"declare: {', '.join(estimates) or 'none'})"
            )
    return list(dict.fromkeys(named)), estimates


@dataclass
class Checked:
    """A configuration checked by :func:`check_config`, every parameter canonical."""

    task: str | None
    task_params: dict
    filter_params: dict  # filter name -> every parameter's value
    dataset_params: dict


def check_config(
    dataset, task, filters, filter_params=None, task_params=None, dataset_params=None, adapter=None
) -> Checked:
    """Check a whole configuration before any data is read; returns it canonical.

    The dataset (its parameters against its generator's declarations or its
    adapter's options), the task (the given one or the dataset's default) and
    its parameters, every filter and its parameters (made, so relations between
    parameters are checked too). A plain file without ``task`` gets its task
    from the frame: its task parameters are checked when the task is made.
    """
    filters = [n for n in filters if not n.startswith("recorded:")]  # recorded: checked with the frame
    extra = [n for n in (filter_params or {}) if n not in filters and not n.startswith("recorded:")]
    if extra:
        raise ReplayError(f"-p {extra[0]}: filter {shown(extra[0])} is not in --filters ({', '.join(filters)})")
    ref = dataset_ref.resolve(dataset, adapter)
    dparams = registry.check_params(ref.target, dataset_params or {}, adapter=adapter)
    if task is None and not ref.is_path:
        task = ref.entry.default_task or None
    tparams = make_task(task, **(task_params or {})).params() if task else dict(task_params or {})
    fparams = {
        name: params_of(make_filter(name, **(filter_params or {}).get(name, {})), "filter", name) for name in filters
    }
    return Checked(task, tparams, fparams, dparams)
