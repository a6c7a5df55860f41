"""Execute a notebook top to bottom with nbclient, in its own folder, and check its outputs.

    python examples/run_notebook.py examples/quickstart.ipynb            # execute in place
    python examples/run_notebook.py examples/quickstart.ipynb -o run.ipynb

A cell that raises fails the run (exit status 1, the cell and its error on stderr). The
executed notebook keeps no per-cell timing metadata, and its outputs must not name a path of
this machine (the checkout, its parent, the home and temporary directories, the Python
prefix): :func:`machine_paths` lists any, and the run fails on them. The data is found by
the notebook itself (``$REPLAY_SHARED`` or ``../shared`` beside the checkout).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path


def execute(path, out=None, *, timeout: int = 900):
    """Run every cell of the notebook ``path`` (working directory: its folder); write it to ``out``
    (default: in place) and return it. Raises nbclient's CellExecutionError on a failing cell."""
    import nbformat
    from nbclient import NotebookClient

    path = Path(path)
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, timeout=timeout, kernel_name="python3", record_timing=False,
                            resources={"metadata": {"path": str(path.parent.resolve())}})
    client.execute()
    for cell in nb.cells:
        cell.metadata.pop("execution", None)
    nb.metadata.pop("widgets", None)
    nbformat.write(nb, Path(out) if out else path)
    return nb


def machine_paths(nb) -> list[str]:
    """Text outputs of ``nb`` that name a directory of this machine (one line each)."""
    here = Path(__file__).resolve().parents[1]
    roots = {str(here), str(here.parent), str(Path.home()), tempfile.gettempdir(), os.path.realpath(sys.prefix)}
    found = []
    for i, cell in enumerate(nb["cells"]):
        for output in cell.get("outputs", []):
            texts = [output.get("text", "")] + [v for k, v in output.get("data", {}).items() if k.startswith("text/")]
            texts += output.get("traceback", [])
            for text in texts:
                text = "".join(text) if isinstance(text, list) else str(text)
                hits = sorted(r for r in roots if r and r != "/" and r in text)
                if hits:
                    found.append(f"cell {i}: {hits[0]}")
    return found


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("notebook")
    parser.add_argument("-o", "--out", default=None, help="write the executed notebook here (default: in place)")
    parser.add_argument("--timeout", type=int, default=900, help="seconds per cell")
    args = parser.parse_args(argv)
    from nbclient.exceptions import CellExecutionError

    try:
        nb = execute(args.notebook, args.out, timeout=args.timeout)
    except CellExecutionError as err:
        print(f"{args.notebook}: a cell failed:\n{err}", file=sys.stderr)
        return 1
    bad = machine_paths(nb)
    if bad:
        print(f"{args.notebook}: outputs name paths of this machine: " + "; ".join(bad), file=sys.stderr)
        return 1
    print(f"{args.notebook}: {len(nb.cells)} cells executed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
