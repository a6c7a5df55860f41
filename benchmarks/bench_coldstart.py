#!/usr/bin/env python
"""Cold start: wall time of the README's first command on a fresh cache, in a subprocess.

    python benchmarks/bench_coldstart.py [--variants cache,numba,fresh,warm] [--json out.json]

The command is read from README.md (the ``replay ...`` after the last ``&&`` of
the first code block that runs ``.venv/bin/replay``; today
``replay eval sim/auv-sonar --runs 20``) and run with the ``replay`` script of
this interpreter, from an empty scratch working directory (its outputs go
there and are deleted), in these states (each in a new scratch directory):

* ``cache``: a fresh, empty ``REPLAY_CACHE_DIR``; numba's on-disk cache as it
  is (``cache=True`` writes it to ``__pycache__`` beside the kernels' source:
  warm once anything has run in this checkout);
* ``numba``: also ``NUMBA_CACHE_DIR`` set to an empty directory, so every
  compiled kernel is compiled again (numba then caches there only);
* ``fresh``: a fresh copy of the package source in its installed layout
  (``replay``, ``adapters`` -> ``replay/adapters``, ``filters`` ->
  ``replay/filters``, from ``[tool.setuptools.package-dir]``; plus the dataset
  manifests), first on ``PYTHONPATH``: numba's caches beside it are absent as
  on a new user's machine after ``pip install``; also an empty
  ``MPLCONFIGDIR`` and Python byte-code written afresh. The issue's cold start;
* ``warm``: the same copy once more: what the user's second run costs.

Install time is excluded (the issue's rule). Target (issue 17; printed
PASS/MISS, never asserted): <= 15 s for a cold start (``cache``, ``numba``, ``fresh``).
"""
from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import gauge

TARGET_S = 15.0
VARIANTS = ("cache", "numba", "fresh", "warm")
COLD = ("cache", "numba", "fresh")


def readme_command(text: str) -> list[str]:
    """The first command of a README: in the first line that runs ``.venv/bin/replay``, the part after
    the last ``&&``, with the ``.venv/bin/`` prefix dropped, as an argument list starting with ``replay``."""
    for line in text.splitlines():
        if ".venv/bin/replay " in line:
            words = shlex.split(line.split("&&")[-1])
            return ["replay"] + words[1:]
    raise ValueError("README.md: no line runs .venv/bin/replay")


def layout(package_dir: dict) -> list[tuple[str, str]]:
    """(source directory, destination path) of each package of ``[tool.setuptools.package-dir]``
    in its installed layout (``{"replay.filters": "filters"}`` -> ``("filters", "replay/filters")``),
    parents first."""
    pairs = [(src, pkg.replace(".", "/")) for pkg, src in package_dir.items()]
    return sorted(pairs, key=lambda p: (p[1].count("/"), p[1]))


def fresh_copy(root: Path, dest: Path) -> Path:
    """Copy the package under ``root`` (a source checkout, or a tree already in installed layout)
    into ``dest`` in its installed layout, without any ``__pycache__``; returns ``dest``."""
    meta = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for src, target in layout(meta["tool"]["setuptools"]["package-dir"]):
        if (root / src).is_dir() and not (dest / target).exists():
            shutil.copytree(root / src, dest / target, ignore=ignore)
    shutil.copytree(root / "datasets", dest / "datasets", ignore=ignore)  # manifests: replay.data.registry
    shutil.copy2(root / "pyproject.toml", dest / "pyproject.toml")  # marks dest as a source tree
    return dest


def replay_script() -> str:
    """The ``replay`` console script of this interpreter's environment (as the README runs it)."""
    p = Path(sys.executable).with_name("replay")
    if not p.exists():
        raise SystemExit(f"bench_coldstart: no replay script beside {Path(sys.executable).name}; "
                         "install the package (pip install -e .)")
    return str(p)


def run_once(argv, env, scratch: Path):
    t0 = time.perf_counter()
    p = subprocess.run(argv, cwd=scratch, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    err = None if p.returncode == 0 else (p.stderr.strip().splitlines() or ["?"])[-1]
    return wall, err


def measure(variants, root: Path, argv, tmp: Path):
    """{variant: {"wall_s", "error"}}: each variant in its own scratch directory under ``tmp``."""
    base = dict(os.environ)
    for k in ("REPLAY_CACHE_DIR", "NUMBA_CACHE_DIR"):
        base.pop(k, None)
    copy = None
    out = {}
    for v in variants:
        d = Path(tempfile.mkdtemp(prefix=f"{v}-", dir=tmp))
        (d / "work").mkdir()
        env = dict(base, REPLAY_CACHE_DIR=str(d / "replay-cache"))
        if v == "numba":
            env["NUMBA_CACHE_DIR"] = str(d / "numba-cache")
        if v in ("fresh", "warm"):
            if copy is None:
                copy = fresh_copy(root, tmp / "package")
            env["PYTHONPATH"] = os.pathsep.join([str(copy)] + ([base["PYTHONPATH"]] if base.get("PYTHONPATH") else []))
            env.pop("PYTHONDONTWRITEBYTECODE", None)
            env["MPLCONFIGDIR"] = str(d / "mpl")
        if v == "fresh":
            check_copy(env, d / "work", copy)
        wall, err = run_once(argv, env, d / "work")
        cache_dir = {"numba": d / "numba-cache", "fresh": copy, "warm": copy}.get(v)
        nbi = len(list(cache_dir.rglob("*.nbi"))) if cache_dir is not None else None
        out[v] = {"wall_s": wall, "error": err, "numba_index_files": nbi}
        print(f"  {v:6s} {wall:7.1f} s" + (f"  FAILED: {err}" if err else "")
              + (f"  (numba cache index files there afterwards: {nbi})" if nbi is not None else ""), flush=True)
    return out


def check_copy(env, cwd: Path, copy: Path) -> None:
    """Exit with one line unless a child with ``env`` imports ``replay.filters`` from ``copy``."""
    p = subprocess.run([sys.executable, "-c", "import replay.filters as f; print(f.__file__)"], cwd=cwd, env=env,
                       capture_output=True, text=True)
    if p.returncode or not Path(p.stdout.strip()).resolve().is_relative_to(copy.resolve()):
        raise SystemExit("bench_coldstart: the fresh copy of the package is not the one imported "
                         "(an editable install that shadows PYTHONPATH?)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variants", default=",".join(VARIANTS), help=f"which of {','.join(VARIANTS)} (comma-separated)")
    ap.add_argument("--json", help="also write the figures, the machine gauge and the verdicts here")
    a = ap.parse_args(argv)
    variants = [v for v in a.variants.split(",") if v]
    if not set(variants) <= set(VARIANTS):
        ap.error(f"--variants: choose among {','.join(VARIANTS)}")
    if "warm" in variants and "fresh" not in variants:
        variants.insert(variants.index("warm"), "fresh")
    import replay

    root = Path(replay.__file__).resolve().parents[1]  # the checkout (or installed-layout tree) under test
    readme = Path(__file__).resolve().parents[1] / "README.md"
    words = readme_command(readme.read_text(encoding="utf-8"))
    cmd = [replay_script()] + words[1:]
    g = gauge.Gauge("bench_coldstart")
    g.start()
    print(f"# bench_coldstart: `{' '.join(words)}` (README.md's first command) from an empty scratch directory")
    with tempfile.TemporaryDirectory(prefix="replay-coldstart-") as tmp:
        res = measure(variants, root, cmd, Path(tmp))
    print()
    print("| state | wall s | what is fresh |")
    print("|---|---:|---|")
    what = {"cache": "REPLAY_CACHE_DIR", "numba": "REPLAY_CACHE_DIR, NUMBA_CACHE_DIR (every kernel compiled)",
            "fresh": "a copy of the package (no numba cache beside it, no byte-code), REPLAY_CACHE_DIR, MPLCONFIGDIR",
            "warm": "nothing: the fresh copy's second run"}
    for v, r in res.items():
        print(f"| {v} | {r['wall_s']:.1f}{' (failed)' if r['error'] else ''} | {what[v]} |")
    print()
    print("Targets (issue 17; reported, never asserted):")
    verdicts = []
    for v in COLD:
        if v in res:
            r = res[v]
            vd = "MISS" if r["error"] else gauge.verdict(r["wall_s"], TARGET_S)
            verdicts.append({"target": f"cold start ({v}) <= {TARGET_S:g} s", "measured": r["wall_s"], "verdict": vd})
            print(f"  {vd}  cold start, {v}: {r['wall_s']:.1f} s, target <= {TARGET_S:g} s")
    info = g.end()
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"command": words, "machine": info, "results": res, "targets": verdicts}, fh, indent=2)
        print(f"wrote {a.json}")
    return 1 if any(r["error"] for r in res.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
