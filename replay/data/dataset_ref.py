"""A dataset as given (``bohai/20220822_0_6``, ``sim/auv-sonar``, a recording's path), resolved once.

:func:`resolve` is the one place that tells a registered id from a plain file and a
simulator from a recording; the rest of the library is handed the :class:`DatasetRef`
(``evaluate``, campaign files, ``replay tune``, ``replay rerun``, the exports) instead of
parsing the string again. The configuration (and so the manifest and every hash) keeps
the id as given: a reference is rebuilt from it, never stored.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from replay.data import registry


@dataclass(frozen=True)
class DatasetRef:
    """What a dataset id names.

    ``kind``: ``sim`` (a registered simulator), ``file`` (a registered recording, found under
    the data directories) or ``path`` (a plain file or bag directory); ``entry``: the registry's
    entry (None for a path); ``path``: the plain file (None otherwise); ``adapter``: the adapter
    reading a recording (None for a simulator, and for a path without ``--adapter``: the file
    tells when it is read, :func:`replay.data.formats.adapter_for`).
    """

    id: str
    kind: str
    entry: registry.Dataset | None = None
    path: Path | None = None
    adapter: str | None = None

    @property
    def is_sim(self) -> bool:
        return self.kind == "sim"

    @property
    def is_path(self) -> bool:
        return self.kind == "path"

    @property
    def target(self):
        """What the registry reads: its entry, or the plain file as given."""
        return self.entry if self.entry is not None else self.id

    @property
    def sequence(self) -> str:
        """The id after its family (``bohai/20220822_0_6`` -> ``20220822_0_6``), a path's file name."""
        return self.path.name if self.path is not None else self.id.split("/", 1)[-1]

    def locate(self, data_dir=None) -> Path | None:
        """The file read: a path's own, a registered recording's first local copy, None for a simulator."""
        if self.path is not None:
            return self.path
        return registry.locate(self.entry, data_dir) if self.kind == "file" else None

    def inputs(self, data_dir=None, mapping=None) -> list[Path]:
        """The files an evaluation of this dataset reads: the recording where it is found, the mapping."""
        found = self.locate(data_dir)
        return [*([found] if found is not None else []), *([Path(mapping)] if mapping else [])]


def simulated(dataset) -> bool:
    """Whether ``dataset`` names a registered simulator (False for a path or an unknown id: never raises)."""
    return (
        isinstance(dataset, str) and (entry := registry.all_datasets().get(dataset)) is not None and entry.kind == "sim"
    )


def resolve(dataset, adapter: str | None = None) -> DatasetRef:
    """``dataset`` (an id, a path, a registry entry or a reference) as a :class:`DatasetRef`.

    An unknown id that does not look like a file raises one line (with close matches); nothing
    is read. ``adapter`` names the adapter of a plain file (``--adapter``).
    """
    if isinstance(dataset, DatasetRef):
        return dataset
    if isinstance(dataset, registry.Dataset):
        return DatasetRef(dataset.id, dataset.kind, entry=dataset, adapter=dataset.adapter)
    if registry.is_path(dataset):
        return DatasetRef(str(dataset), "path", path=Path(dataset).expanduser(), adapter=adapter)
    entry = registry.get(dataset)
    return DatasetRef(entry.id, entry.kind, entry=entry, adapter=entry.adapter)
