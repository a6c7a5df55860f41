"""The options of ``replay score`` and ``replay.score`` that decide its numbers, as one record
(:class:`ScoreOptions`): built once at the edge (the CLI from its options, the API from its keywords and
their declarations, ``replay.api_args.ARGS["score"]``) and passed whole. Its :meth:`~ScoreOptions.settings`
are the keyword arguments of :func:`replay.trajectory.score` and what the configuration hash covers."""

from __future__ import annotations

from dataclasses import dataclass

# evo's trajectory options (replay.trajectory.prepare) and their defaults: in the settings only where
# they differ from these (so the hash of a plain call is unchanged)
PREPARE = {
    "sync_method": "nearest",
    "t_start": None,
    "t_end": None,
    "downsample": None,
    "motion_filter": None,
    "project_to_plane": None,
}


@dataclass(frozen=True)
class ScoreOptions:
    """Every field given (the defaults are the declarations', applied at the edge)."""

    align: str  # none, yaw, se3, sim3, scale (the CLI's -a/-s flags resolved)
    n_to_align: int | None
    align_origin: bool
    t_max_diff: float
    t_offset: float
    relations: list  # pose relations, each once, in the order given
    rpe: bool
    delta: float | None
    delta_unit: str
    delta_tol: float
    all_pairs: bool
    pairs_from_reference: bool
    lengths: list | None  # parsed (replay.trajectory.lengths.parse)
    lengths_method: str
    sync_method: str
    t_start: float | None
    t_end: float | None
    downsample: int | None
    motion_filter: tuple | None
    project_to_plane: str | None
    lost_threshold: float | None
    lost_steps: int

    @property
    def want_rpe(self) -> bool:
        """Whether the RPE is scored (``rpe``, a ``delta`` or ``all_pairs``)."""
        return self.rpe or self.delta is not None or self.all_pairs

    def settings(self) -> dict:
        """The keyword arguments of :func:`replay.trajectory.score` (and of the configuration hash):
        ``delta`` None for no RPE; ``lengths`` only when asked for; evo's trajectory options
        (:data:`PREPARE`) only where they differ from their defaults."""
        out = dict(
            align=self.align,
            n_to_align=self.n_to_align,
            align_origin=self.align_origin,
            t_max_diff=self.t_max_diff,
            t_offset=self.t_offset,
            relations=list(self.relations),
            delta=(self.delta or 1.0) if self.want_rpe else None,
            delta_unit=self.delta_unit,
            all_pairs=self.all_pairs,
            rel_tol=self.delta_tol,
            pairs_from_reference=self.pairs_from_reference,
        )
        if self.lengths:
            out.update(lengths=self.lengths, lengths_method=self.lengths_method)
        out.update({k: getattr(self, k) for k, default in PREPARE.items() if getattr(self, k) != default})
        return out
