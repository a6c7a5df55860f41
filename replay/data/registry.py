"""The dataset registry: manifests, local copies, and loading a dataset as a Frame.

Manifests are TOML files ``datasets/*.toml`` (format: ``datasets/README.md``).
They are read from ``<repo>/datasets`` in a source checkout, otherwise from
``sys.prefix/share/replay/datasets`` where ``pip install`` puts them.

A file dataset is searched for, in this order, in: the ``data_dir`` argument,
each directory of ``$REPLAY_DATA_DIR`` (``os.pathsep``-separated), then the user
cache (``$REPLAY_CACHE_DIR``, else ``$XDG_CACHE_HOME/replay``, else
``~/.cache/replay``). In each root the file may sit flat (``root/<file>``), in
the upstream layout (``root/<upstream_path>``), or either way under a folder
named after the id's prefix (``root/bohai/...``).

Registered upstream checksums and sizes, and the checks of a local copy, are in
``replay/data/checksums.py`` (re-exported here).
"""

from __future__ import annotations

import difflib
import functools
import inspect
import sys
from dataclasses import dataclass, fields
from importlib import import_module
from pathlib import Path

import numpy as np

from replay.data import fault_apply, views
from replay.data.checksums import (
    CHECKSUMS_FILE,
    CONTENT_CHECKED,
    check_file,
    check_loaded,  # noqa: F401
    read_checksums,
    sha256_file,
    with_registered,
)
from replay.util.data_dirs import cache_dir, cache_variable, check_data_dir, search_roots  # noqa: F401
from replay.util import tomlfile, tomlschema
from replay.util.errors import DataError, ReplayError, shown
from replay.util.params import Param, validate
from replay.util.progress import Loading
from replay.util.regular import check_regular
from replay.util.tomlschema import Table
from replay.adapters.options import check
from replay.data.plugins import ADAPTERS, dataset_entries  # the built-in adapters and the plugins
from replay.data.formats import adapter_for, looks_like_path

# Adapter used for a plain file path, by extension.
FIRST = Param("first", int, None, "use only the first N samples (null: all)", unit="samples", low=1, optional=True)


@dataclass(frozen=True)
class Dataset:
    """One manifest entry."""

    id: str
    kind: str  # "file" (a recording to locate or download) or "sim" (generated)
    description: str = ""
    default_task: str = ""
    adapter: str | None = None  # file datasets: name in replay.adapters.ADAPTERS
    generator: str | None = None  # sim datasets: "module:function"
    file: str | None = None
    upstream_path: str | None = None
    url: str | None = None
    sha256: str | None = None  # the registered upstream checksum; None when not registered
    size: int | None = None  # bytes, when registered
    site: str = ""
    rows: int | None = None
    span_s: float | None = None
    license: str = ""
    citation: str = ""
    manifest: str = ""  # the manifest file this entry came from

    @property
    def namespace(self) -> str:
        """The id's prefix, e.g. "bohai"."""
        return self.id.split("/", 1)[0]


MANIFEST_KEYS = {f.name for f in fields(Dataset)} - {"kind", "manifest"}
_TYPES, _LOW = {"str": str, "int": int, "float": float}, {"size": 1, "rows": 0, "span_s": 0}
MANIFEST = Table(  # a manifest's [[dataset]] entry, declared once: by the fields of Dataset (their types)
    "dataset",
    "",
    tuple(
        Param(f.name, _TYPES[f.type.split(" |")[0]], None, f.name, low=_LOW.get(f.name), optional=True)
        for f in fields(Dataset)
        if f.name in MANIFEST_KEYS
    ),
)


# ---------------------------------------------------------------- manifests


def manifests_dir() -> Path:
    """Where the ``*.toml`` manifests are: the source tree first, then the install prefix."""
    repo = Path(__file__).resolve().parents[2]
    source = repo / "datasets"
    if (repo / "pyproject.toml").is_file() and any(source.glob("*.toml")):
        return source
    return Path(sys.prefix) / "share" / "replay" / "datasets"


def all_datasets(directory: str | Path | None = None) -> dict[str, Dataset]:
    """Every dataset of every manifest, by id (manifests read once, then cached); without
    ``directory``, also those of the ``replay.datasets`` entry points (:mod:`replay.data.plugins`)."""
    out = dict(_read_manifests(str(Path(directory) if directory else manifests_dir())))
    if directory is None:
        out.update(_plugins()[0])
    return out


def plugin_problems() -> list[str]:
    """One line per dataset plugin that cannot be used (``replay list`` prints them)."""
    return _plugins()[1]


def _plugins() -> tuple[dict, list]:

    entries, _, problems = dataset_entries(_read_manifests(str(manifests_dir())))
    out, problems = {}, list(problems)
    for ds_id, where, entry in entries:
        try:
            out[ds_id] = _make_dataset(where, dict(entry))
        except ReplayError as err:
            problems.append(str(err))
    return out, problems


@functools.lru_cache(maxsize=None)
def _read_manifests(directory: str) -> dict[str, Dataset]:
    paths = sorted(Path(directory).glob("*.toml"))
    if not paths:
        raise ReplayError(f"no dataset manifests (*.toml) found in {directory}")
    out: dict[str, Dataset] = {}
    for path in paths:
        for ds in _read_manifest(path):
            if ds.id in out:
                raise ReplayError(f"{path}: dataset {ds.id} is also defined in {out[ds.id].manifest}")
            out[ds.id] = ds
    return out


def _read_manifest(path: Path) -> list[Dataset]:
    doc, _ = tomlfile.load(path, "a dataset manifest")
    entries = doc.pop("dataset", [])
    defaults = doc  # top-level keys apply to every entry
    if not isinstance(entries, list):
        raise ReplayError(f"{path}: `dataset` must be an array of tables ([[dataset]])")
    return [_make_dataset(path, {**defaults, **entry}) for entry in entries]


def _make_dataset(path: Path, entry: dict) -> Dataset:
    ds_id = entry.get("id")
    where = f"{path}: dataset {ds_id}"
    if not isinstance(ds_id, str) or "/" not in ds_id:
        raise ReplayError(f"{path}: every [[dataset]] needs an id of the form 'prefix/name' (got {shown(ds_id)})")
    tomlschema.check(MANIFEST, entry, lambda key, text: ReplayError(f"{where}: {text}"))
    if ("file" in entry) == ("generator" in entry):
        raise ReplayError(f"{where}: give exactly one of `file` (a recording) or `generator` (a simulator)")
    kind = "file" if "file" in entry else "sim"
    if kind == "file" and not entry.get("adapter"):
        raise ReplayError(f"{where}: a file dataset needs an `adapter`")
    if kind == "sim" and ":" not in entry["generator"]:
        raise ReplayError(f"{where}: `generator` must be 'module:function'")
    sha = entry.get("sha256")
    if sha is not None:
        sha = sha.lower()
        if len(sha) != 64 or any(c not in "0123456789abcdef" for c in sha):
            raise ReplayError(f"{where}: sha256 must be 64 hex digits")
        entry["sha256"] = sha
    return with_registered(Dataset(kind=kind, manifest=str(path), **entry), where)


def ids() -> list[str]:
    return list(all_datasets())


def local_ids(prefix: str = "", data_dir: str | Path | None = None) -> list[str]:
    """The sorted ids starting with ``prefix`` whose file is found locally (:func:`locate`; never a sim)."""
    return [i for i in sorted(all_datasets()) if i.startswith(prefix) and locate(i, data_dir)]


def get(dataset_id: str) -> Dataset:
    """The dataset with this id; an unknown id raises ReplayError with close matches."""
    known = all_datasets()
    if dataset_id in known:
        return known[dataset_id]

    conflict = dataset_entries()[1].get(dataset_id)
    if conflict:
        raise ReplayError(conflict)
    raise ReplayError(
        f"unknown dataset {shown(dataset_id)}{_suggest(dataset_id, known)}; `replay datasets list` shows them all"
    )


def _suggest(query: str, known) -> str:
    # compare with the full ids and with the part after the prefix
    keys = {}
    for ds_id in known:
        keys.setdefault(ds_id, ds_id)
        keys.setdefault(ds_id.split("/", 1)[1], ds_id)
    close = difflib.get_close_matches(query, list(keys), n=6, cutoff=0.6)
    matches = list(dict.fromkeys(keys[k] for k in close))[:3]
    if not matches:
        return ""
    listed = matches[0] if len(matches) == 1 else f"{', '.join(matches[:-1])} or {matches[-1]}"
    return f" (did you mean {listed}?)"


# ---------------------------------------------------------------- local copies


def candidates(ds: Dataset, root: Path) -> list[Path]:
    """Where in one root the file may be: flat, upstream layout, and both under <prefix>/."""
    rels = [ds.file] + ([ds.upstream_path] if ds.upstream_path else [])
    paths = [root / r for r in rels] + [root / ds.namespace / r for r in rels]
    return list(dict.fromkeys(paths))


def locate(ds: Dataset | str, data_dir: str | Path | None = None) -> Path | None:
    """The first existing local copy of a file dataset, or None (always None for sims)."""
    ds = get(ds) if isinstance(ds, str) else ds
    if ds.kind != "file":
        return None
    for root in search_roots(data_dir):
        for path in candidates(ds, root):
            if path.is_file():
                return path
    return None


# ---------------------------------------------------------------- loading


def load_frame(dataset, *, data_dir=None, rng=None, first: int | None = None, adapter: str | None = None, **params):
    """Load a dataset id, a :class:`Dataset`, or a plain file path as a Frame.

    File datasets are located (see :func:`locate`) and read by their adapter with
    ``params``; sim datasets are generated by ``generator(rng, **params)`` where
    ``rng`` is a seed, a ``numpy.random.Generator`` or None. ``params`` are
    checked first (:func:`check_params`); their views (:mod:`replay.data.views`) cut the frame, then
    ``first`` keeps its first samples. A local copy whose sha256 differs from the manifest still
    loads (users may edit files) but gets a "flagged" entry in the frame report. ``adapter`` overrides
    the adapter chosen for a plain path.
    """
    first = FIRST.check(first)
    check_data_dir(data_dir)
    shown = str(dataset.id if isinstance(dataset, Dataset) else dataset)
    chosen, params = views.split(check_params(dataset, params, adapter=adapter))
    faulty = fault_apply.stream(rng) if chosen.get("fault") else None  # before a simulator draws from rng
    if isinstance(dataset, Dataset):
        ds = dataset
    elif is_path(dataset):
        frame = cut(_load_path(Path(dataset), adapter, params), chosen, first, shown)
        return fault_apply.apply(frame, chosen.get("fault"), faulty, shown)
    else:
        ds = get(dataset)
    frame = _load_sim(ds, rng, params) if ds.kind == "sim" else _load_file(ds, data_dir, params)
    frame.meta["dataset"] = ds.id
    return fault_apply.apply(cut(frame, chosen, first, shown), chosen.get("fault"), faulty, shown)


def cut(frame, chosen: dict, first: int | None, shown: str):
    """``frame`` as read, cut by its views ``chosen`` (:mod:`replay.data.views`; faults are applied per
    run elsewhere) and then to its ``first`` samples: a new frame, ``frame`` itself unchanged (it may
    be a cached read that other views are cut from)."""
    return views.apply(frame, chosen, shown).head(first)


def is_path(dataset) -> bool:
    """Whether ``dataset`` names a plain file (not a registered id)."""
    return isinstance(dataset, Path) or (dataset not in all_datasets() and looks_like_path(dataset))


# ---------------------------------------------------------------- parameters


def generator(ds: Dataset):
    """The generator function of a sim dataset (its ``PARAMS`` are its declared parameters)."""
    module, func = ds.generator.split(":")
    try:
        make_frame = getattr(import_module(module), func)
    except (ImportError, AttributeError) as e:
        raise ReplayError(f"dataset {ds.id}: generator {ds.generator} is not available ({e})") from None
    if getattr(make_frame, "PARAMS", None) is None:
        raise ReplayError(
            f"dataset {ds.id}: generator {ds.generator} declares no parameters (decorate it with replay.sim.generator)"
        )
    return make_frame


def adapter_options(name: str):
    """The options (Param) adapter ``name`` declares; None: a plugin's ``load`` declaring none."""
    return getattr(_adapter(name), "PARAMS", None)


def check_params(dataset, params: dict, *, adapter: str | None = None) -> dict:
    """``params`` of a dataset checked, before any data is read; returns them canonical.

    A sim dataset's are checked against its generator's declarations (unknown
    names, types, bounds) and returned with every default filled in. A file's
    (a dataset id or a plain path) are its adapter's declared options, returned
    checked (only those given: :mod:`replay.adapters.options`).
    Every dataset also takes the views (:data:`replay.data.views.VIEW_PARAMS`), returned
    canonical and only when given (so a configuration without them keeps its hash).
    """
    chosen, params = views.split(dict(params or {}))
    if isinstance(dataset, Dataset):
        ds = dataset
    elif is_path(dataset):
        path = Path(dataset).expanduser()
        name = adapter or (adapter_for(path) if path.exists() or path.suffix else None)
        return {
            **(_check_options(name, params) if name else params),
            **views.check(chosen, f"dataset {shown(dataset)}"),
        }
    else:
        ds = get(dataset)
    own = (
        validate(generator(ds).PARAMS, params, f"dataset {shown(ds.id)}")
        if ds.kind == "sim"
        else _check_options(ds.adapter, params)
    )
    return {**own, **views.check(chosen, f"dataset {shown(ds.id)}")}


def _check_options(adapter: str, params: dict) -> dict:
    """``params`` checked against ``adapter``'s declarations; a plugin declaring none: their names."""

    declared = adapter_options(adapter)
    if declared is not None:
        return check(adapter, declared, params)
    sig = inspect.signature(_adapter(adapter)).parameters.values()
    names = [p.name for p in sig if p.kind == p.KEYWORD_ONLY]
    unknown = [k for k in params if k not in names]
    if unknown and not any(p.kind == p.VAR_KEYWORD for p in sig):
        raise ReplayError(
            f"adapter {adapter}: unknown option {shown(unknown[0])} (known: {', '.join(names) or 'none'})"
        )
    return params


def _adapter(name: str):

    try:
        return ADAPTERS.load(name)
    except ImportError as e:
        raise ReplayError(f"adapter {name} is not available: {e}") from None


def _read(adapter: str, path: Path, params: dict):
    """The adapter's frame of ``path``, with a heartbeat on stderr when reading takes more than a few
    seconds (:class:`replay.util.progress.Loading`; quiet under ``-q``)."""
    load = _adapter(adapter)
    try:
        size = sum(f.stat().st_size for f in path.iterdir()) if path.is_dir() else path.stat().st_size
    except OSError:
        size = None
    with Loading(path.name, size):
        return load(path, **params)


def _load_path(path: Path, adapter: str | None, params: dict):
    path = path.expanduser()
    bag_dir = path.is_dir() and (path / "metadata.yaml").is_file()  # a ROS 2 bag is a directory
    check_regular(path, "a dataset", dir_ok=True)
    if not (path.is_file() or bag_dir):
        raise DataError(path, "no such file")
    frame = _read(adapter or adapter_for(path), path, params)
    sha = frame.meta.get("sha256") if bag_dir else sha256_file(path)
    frame.meta.update(dataset=str(path), path=str(path), sha256=sha, checksum="unknown")
    return frame


def _load_file(ds: Dataset, data_dir, params: dict):
    path = locate(ds, data_dir)
    if path is None:
        where = ", ".join(str(r) for r in search_roots(data_dir))
        raise ReplayError(
            f"dataset {ds.id} not found in {where}; run `replay datasets fetch {ds.id}` or pass --data-dir"
        )
    frame = _read(ds.adapter, path, params)
    check_loaded(ds, path, frame)  # sha256, checksum status, content_checked; flags; another sequence refused
    return frame


def _load_sim(ds: Dataset, rng, params: dict):
    frame = generator(ds)(np.random.default_rng(rng), **params)
    frame.meta.setdefault("generator", ds.generator)
    if isinstance(rng, (int, np.integer)):
        frame.meta.setdefault("seed", int(rng))
    return frame
