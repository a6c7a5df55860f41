"""One output of a command, written so that a crash leaves the old output or the new one, never a mix.

Every command that writes a result writes it through an :class:`OutputSet`: ``replay eval`` (its
``--out`` or a numbered run directory: :mod:`replay.outputs.eval_output`), the MCAP / ROS 2 bag
exports (:mod:`replay.outputs.export_safety`), ``replay score --save-results``
(:mod:`replay.trajectory.archive`), the single output files (``-o``, ``--plot``,
``--write-mapping``: :mod:`replay.util.outfile`), and, checked the same way though they are
stores filled unit by unit under their own lock, the directories of ``replay campaign run``
(:func:`replay.campaign.lock.output_set`), ``replay tune`` and ``replay eval --tune``
(:mod:`replay.tune.write`). Its steps:

1. **claim** (:meth:`OutputSet.claim`): hold the lock ``.NAME.lock`` beside the target for the
   run (:mod:`replay.util.lock`); a second writer refuses in one line naming the holder's pid, or
   waits. (A numbered run directory is claimed by :func:`replay.outputs.rundirs.claimed_run_dir`.)
2. **check** (:meth:`OutputSet.check`, before computing and again at publication): not onto,
   around or inside an input (the inputs are given to it) nor another target of the same
   command; a writable location on a file system neither read-only nor full; an existing target
   only if it is our own earlier output of the same kind (the ownership ``rule``: by default the
   marker of :func:`replay.util.staging.check_replaceable`).
3. **stage** (:meth:`OutputSet.staged`): a temporary sibling ``.NAME.staging-PID`` (a directory,
   or a file with ``file=True``) to write into (``nested``: the directory ``.NAME.staging-PID/NAME``).
4. **publish** (at the end of the ``staged`` block): the sibling fsynced, the target checked
   again and replaced in one step (:func:`replay.util.staging.publish_dir` for a directory,
   ``rename`` for a file), the parent fsynced.
5. **recover** (:meth:`OutputSet.recover`, at the start of each write): what dead writers left
   beside the target removed, an old set they had moved aside put back.

Each refusal and each failed write is one line naming the option (``what``) and the path.
"""

from __future__ import annotations

import json
import os
import shutil
from contextlib import contextmanager
from pathlib import Path

from replay.util.errors import ReplayError
from replay.util.files import check_writable, refuse_overlap
from replay.util.lock import lock_file
from replay.util.staging import (
    MARKER,
    fault_point,
    fsync_path,
    tree_files,
    check_replaceable,
    check_space,
    fsync_tree,
    publish_dir,
    recover,
)

KEPT = "cannot write ({why}); the previous output, if any, is unchanged"  # the failed-write line of a set


class OutputSet:
    """One output (a directory set, or a file with ``file=True``) at ``target`` (module docstring).

    ``kind``: what it is (``"replay eval"``: written into the marker of a directory set, and an
    existing set is replaced only if its marker names this kind, or ``legacy(path)`` accepts it);
    ``rule(path, shown)``: instead, the ownership test of an existing target (raises when it may not
    be replaced); ``inputs``: what the command reads; ``others``: the other targets of the command;
    ``failed``: the line of a failed write (``{why}``: the system's reason).
    """

    def __init__(
        self, target, kind=None, *, what="output", inputs=(), others=(), legacy=None, rule=None, file=False, failed=KEPT
    ):
        self.shown, self.target = target, Path(target)
        self.kind, self.what, self.legacy = kind, what, legacy
        self.inputs = [p for p in inputs if p is not None]
        self.others = [p for p in others if p is not None]
        self.rule = rule or self._marker_rule
        self.file, self.failed = file, failed

    # ------------------------------------------------------------ check

    def _marker_rule(self, path: Path, shown) -> None:
        if self.kind is None:  # no way to tell an output of ours: only an absent or empty target
            if os.path.lexists(path) and (not path.is_dir() or path.is_symlink() or any(path.iterdir())):
                raise ReplayError(f"{self.what} {shown}: exists; refusing to replace it: choose another {self.what}")
            return
        check_replaceable(path, self.kind, self.what, self.legacy, shown=shown)

    def check(self, contents: bool = True) -> Path:
        """Every refusal that can be made before computing (one line each); returns the target
        resolved. ``contents=False``: the location only (a directory claimed and filled later)."""
        target = self._apart()
        check_space(self.shown, self.what)
        check_writable(self.shown, self.what)
        if contents:
            self.rule(target if self.kind else Path(self.shown), self.shown)
        return target

    def _apart(self) -> Path:
        """Refuse a target onto, around or inside an input or another target; returns it resolved."""
        target = refuse_overlap(self.shown, self.inputs, self.what)
        for other in self.others:
            b = Path(other).resolve()
            if target == b or target.is_relative_to(b) or b.is_relative_to(target):
                raise ReplayError(
                    f"{self.what} {self.shown}: overlaps the other export target {other}; give separate paths"
                )
        return target

    # ------------------------------------------------------------ claim

    @contextmanager
    def claim(self, wait: bool = False, who: str = "replay eval"):
        """Hold the target's lock (``.NAME.lock`` beside it) for the block; another process (a
        ``who``) holding it: refused in one line naming its pid, or with ``wait`` waited for."""
        target = self.target.resolve()
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ReplayError(f"{self.what} {self.shown}: cannot create {target.parent} ({err.strerror})") from None
        busy = (
            f"{self.what} {self.shown}: another {who} process (pid {{pid}}) is writing to it; "
            "wait for it to finish or pass --wait"
        )
        with lock_file(target.parent / f".{target.name}.lock", wait, busy=busy, what=f"the {self.what} lock"):
            yield target

    # ------------------------------------------------------------ stage, publish, recover

    def recover(self) -> None:
        """Clean up after writers of this target that died (:func:`replay.util.staging.recover`)."""
        recover(self.target.resolve())

    def staging(self) -> Path:
        """The temporary sibling this process writes into: ``.NAME.staging-PID``."""
        target = self.target.resolve()
        return target.with_name(f".{target.name}.staging-{os.getpid()}")

    @contextmanager
    def staged(self, nested: bool = False):
        """A fresh temporary sibling to write the whole output into (``nested``: a path named like the
        target inside it, not yet made, for a writer that makes the directory itself and names its
        files after it: a ROS 2 bag). On a normal exit it is fsynced (a set gets its marker listing
        its files), the target is checked again (not an input, ours: it may have changed during the
        computation) and replaced in one step; on an exception the sibling is removed and the target
        untouched. An ``OSError`` (full disk, read-only, file too large) is one line."""
        target, staging, made = self.target.resolve(), self.staging(), []
        inner = staging / target.name if nested else staging
        try:
            self._apart()
            self.recover()
            self.rule(target if self.kind else self.target, self.shown)
            made = [q for q in (target.parent, *target.parent.parents) if not q.exists()][::-1]
            for d in made:
                d.mkdir()
            _remove(staging)
            if not self.file:
                staging.mkdir()
            yield inner
            fault_point("written")
            self._publish(inner, target)
            if nested:
                _remove(staging)
        except BaseException as exc:
            _remove(staging)
            for d in reversed(made):
                try:
                    d.rmdir()
                except OSError:
                    pass
            if isinstance(exc, OSError):
                raise ReplayError(
                    f"{self.what} {self.shown}: " + self.failed.format(why=exc.strerror or str(exc))
                ) from None
            raise

    def _publish(self, staging: Path, target: Path) -> None:
        if self.file:
            fsync_path(staging)
        else:
            if self.kind:
                mark = {"tool": "replay", "kind": self.kind, "files": tree_files(staging)}
                (staging / MARKER).write_text(json.dumps(mark, indent=1) + "\n")
            fsync_tree(staging)
        self._apart()
        self.rule(target if self.kind else self.target, self.shown)
        if self.file:
            os.replace(staging, target)
            fsync_path(target.parent, directory=True)
        else:
            publish_dir(staging, target)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)
