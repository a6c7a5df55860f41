"""Where ``replay eval`` writes, safe with any number of concurrent evaluations.

Numbered run directories ``runs/<dataset>/<task>/NNN`` are *claimed* when a run starts
(:func:`claimed_run_dir`): under the lock of ``runs/<dataset>/<task>`` (a ``flock`` on the
directory itself, held for milliseconds) the next number is created with ``mkdir`` (the next
one on a collision) and a claim file ``NNN/.replay-claim`` holding the pid is created and
locked for the whole run. A directory holding only a claim is a run being computed: no other
process takes or replaces it. The finished set replaces the claimed directory in one step
(:meth:`replay.util.output_set.OutputSet.staged`), which checks the claim again. A claim whose process
died (the kernel released its lock) and staging directories of dead processes are removed by
the next claim. ``latest`` is swapped atomically (a new symbolic link renamed over it) to the
highest-numbered finished directory, under the same lock.

An explicit ``--out DIR`` is held for the whole run by the lock file ``.DIR.lock`` beside it
(:func:`out_locked`: :meth:`replay.util.output_set.OutputSet.claim`): a second writer refuses
in one line naming the holder's pid, or with ``--wait`` waits for it. The lock file stays.
"""

from __future__ import annotations

import os
import re
import shutil
from contextlib import ExitStack, contextmanager
from pathlib import Path

from replay.outputs.files import CLAIM, KIND, claim_holder, legacy_output, readable_name
from replay.util.errors import ReplayError
from replay.util.lock import lock_file
from replay.util.output_set import OutputSet
from replay.util.staging import read_marker, recover


def _numbered(base: Path) -> list[Path]:
    try:
        names = os.listdir(base)
    except OSError:
        return []
    return [base / n for n in names if n.isdigit() and (base / n).is_dir() and not (base / n).is_symlink()]


def new_run_dir(dataset: str, task: str, root: Path = Path("runs")) -> Path:
    """The number the next run would take, ``runs/<dataset>/<task>/NNN`` (001, 002, ...): a path
    to check before claiming; :func:`claimed_run_dir` takes the number."""
    base = root / readable_name(dataset) / task
    return base / f"{max((int(p.name) for p in _numbered(base)), default=0) + 1:03d}"


def _base_locked(base: Path):
    return lock_file(base, wait=True, busy="", what="the run directory")


def _clean(base: Path) -> None:
    """Remove what dead runs left in ``base`` (under its lock): staging directories, claims of dead
    processes, empty numbered directories, a half-made ``latest`` link."""
    for name in os.listdir(base):
        if m := re.match(r"^\.(\d+)\.(staging|old)-\d+$", name):
            recover(base / m.group(1))
        elif re.match(r"^\.latest\.\d+\.tmp$", name):  # made and renamed only under the lock: a leftover
            (base / name).unlink(missing_ok=True)
    for d in _numbered(base):
        try:
            entries = os.listdir(d)
        except OSError:
            continue
        if not entries or (entries == [CLAIM] and claim_holder(d) is None):
            shutil.rmtree(d, ignore_errors=True)


@contextmanager
def claimed_run_dir(dataset: str, task: str, root: Path = Path("runs")):
    """Claim the next numbered directory ``runs/<dataset>/<task>/NNN`` for the block (module
    docstring); if no set was published into it by the end of the block, it is removed."""
    base = root / readable_name(dataset) / task
    made = [p for p in (base, *base.parents) if not p.exists() and p != Path(".")]  # deepest first
    with ExitStack() as stack:
        d = _claim(base, stack)
        try:
            yield d
        finally:  # nothing published (an error, or no set written): the claim goes
            if os.path.isdir(d) and os.listdir(d) == [CLAIM]:
                shutil.rmtree(d, ignore_errors=True)
                _remove_empty(made)


def _claim(base: Path, stack: ExitStack) -> Path:
    """Make ``base``, take its next number and lock the claim in ``stack``. A refused run may remove
    an empty ``base`` (:func:`_remove_empty`) between this run's mkdir and its lock: then again."""
    for attempt in range(10):
        try:
            base.mkdir(parents=True, exist_ok=True)
            with _base_locked(base):
                if not base.is_dir():  # removed by a refused run after our mkdir: make it again
                    continue
                _clean(base)
                n = max((int(p.name) for p in _numbered(base)), default=0) + 1
                while True:
                    d = base / f"{n:03d}"
                    try:
                        d.mkdir()
                        break
                    except FileExistsError:
                        n += 1
                stack.enter_context(lock_file(d / CLAIM, busy=f"{d}: claimed by pid {{pid}}", what="the claim"))
                return d
        except (OSError, ReplayError) as err:
            if base.is_dir() or attempt == 9:
                if isinstance(err, ReplayError):
                    raise
                raise ReplayError(f"{base}: cannot create a run directory ({err.strerror})") from None
    raise ReplayError(f"{base}: cannot create a run directory (removed again and again)")


def _remove_empty(made: list[Path]) -> None:
    """The directories a refused run created (``runs/<dataset>/<task>``, deepest first) removed while
    empty, the task's under its lock: a refused ``replay eval`` leaves nothing behind. One another
    run uses is not empty (its claim is in it) and stays; a run that finds it gone makes it again."""
    if not made:
        return
    try:
        with _base_locked(made[0]):
            os.rmdir(made[0])
    except (OSError, ReplayError):  # not empty (another run's), or already gone
        return
    for p in made[1:]:
        try:
            os.rmdir(p)
        except OSError:
            return


def finished(path: Path) -> bool:
    """Whether ``path`` holds a complete ``replay eval`` output."""
    mark = read_marker(path)
    return mark.get("kind") == KIND if mark else legacy_output(path)


def mark_latest(out: Path) -> None:
    """Point ``<out's parent>/latest`` at the highest-numbered finished directory beside ``out``
    (a relative symbolic link renamed over the old one: atomic), under the lock of the parent."""
    base = Path(out).parent
    with _base_locked(base):
        done = [p for p in _numbered(base) if finished(p)]
        if not done:
            return
        newest = max(done, key=lambda p: int(p.name))
        link, tmp = base / "latest", base / f".latest.{os.getpid()}.tmp"
        try:
            if tmp.is_symlink():
                tmp.unlink()
            os.symlink(newest.name, tmp)
            os.replace(tmp, link)
        except OSError:  # a file system without symbolic links: the numbered directory is enough
            tmp.unlink(missing_ok=True)


def out_locked(out, wait: bool = False):
    """Hold ``--out``'s lock (``.NAME.lock`` beside it) for the block: :meth:`OutputSet.claim`."""
    return OutputSet(out, what="--out").claim(wait)
