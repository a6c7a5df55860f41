"""``replay eval``'s output set: its directory (``--out``, or a new numbered run directory) and its
exports (``--mcap``, ``--ros2-bag``), checked before the computation, claimed for it and published
after it, each step through :class:`replay.util.output_set.OutputSet`.

``with output.claimed(wait) as out:`` (everything checked before anything is computed, then the
numbered directory claimed, or ``--out``'s lock held, and everything checked again now that no
other ``replay eval`` writes there), compute, ``output.publish(ev)`` (checked once more, the
set written in one step, ``latest`` moved to a numbered directory).
"""

from __future__ import annotations

from contextlib import ExitStack, contextmanager
from pathlib import Path

from replay.outputs.export_safety import check_eval_exports
from replay.outputs.files import check_location, check_output, eval_inputs, output_set, write_all
from replay.outputs.rundirs import claimed_run_dir, mark_latest, new_run_dir
from replay.util.errors import ReplayError


class EvalOutput:
    """Where one ``replay eval`` writes. ``dataset``: as given (it names a numbered directory);
    ``ref``: it resolved; ``out``: ``--out`` or None for a numbered directory; ``force``: replace
    an earlier output at ``--out``; ``exports``: (``--mcap``, ``--ros2-bag``), each or None."""

    def __init__(self, ref, dataset, task, out=None, *, force=False, mapping=None, exports=(None, None), data_dir=None):
        self.ref, self.dataset, self.task, self.mapping, self.data_dir = ref, dataset, task, mapping, data_dir
        self.numbered, self.force, self.exports = out is None, force, exports
        self.out = None if out is None else Path(out)
        self.inputs = eval_inputs(ref, data_dir, mapping)

    def check(self) -> None:
        """Every refusal that can be made before the computation (one line each)."""
        if self.numbered:  # the location, before claiming a number in it
            place = new_run_dir(self.dataset, self.task)
            check_location(place, self.inputs, "--out")
        else:
            place = self.out
            check_output(place, self.inputs, "--out")
            self._fresh(place)
        check_eval_exports(place, *self.exports, self.dataset, self.mapping, self.data_dir)

    @contextmanager
    def claimed(self, wait: bool = False):
        """The output directory claimed for the block (a new numbered one, or ``--out`` under its
        lock; ``wait``: for another writer of ``--out``), checked before (:meth:`check`: a refused
        run claims nothing) and again once claimed; yields it."""
        self.check()
        with ExitStack() as held:
            if self.numbered:
                self.out = held.enter_context(claimed_run_dir(self.dataset, self.task))
            else:
                held.enter_context(output_set(self.out).claim(wait))
            check_output(self.out, self.inputs, "--out")
            self._fresh(self.out)
            check_eval_exports(self.out, *self.exports, self.dataset, self.mapping, self.data_dir)
            yield self.out

    def publish(self, ev) -> dict:
        """Write the evaluation ``ev`` as one set into the claimed directory; returns its paths."""
        self._fresh(self.out)  # again at publication
        paths = write_all(ev, self.out, what="--out")
        if self.numbered:
            mark_latest(self.out)
        return paths

    def _fresh(self, out: Path) -> None:
        """Without --force, refuse an --out that holds an output (checked at the start and again
        before publication, under --out's lock); a claimed numbered directory is ours."""
        if not (self.numbered or self.force) and out.is_dir() and any(out.iterdir()):
            raise ReplayError(
                f"--out {out}: holds an earlier replay eval output; pass --force to replace it, "
                "or leave out --out for a new numbered directory"
            )
