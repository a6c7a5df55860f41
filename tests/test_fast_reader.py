"""The TUM reader's one-pass path (numpy's C parser) gives the line-by-line reader's values bit for bit,
and leaves every irregular file to it (which names the line)."""
from pathlib import Path

import numpy as np
import pytest

from replay.trajectory import files
from replay.util.errors import DataError


def test_fast_path_equals_the_line_by_line_reader(tmp_path):
    rng = np.random.default_rng(1)
    vals = rng.standard_normal((3000, 8)) * 10.0 ** rng.integers(-300, 300, (3000, 8))
    for k, fmt in enumerate((repr, lambda v: f"{v:.12g}", lambda v: f"{v:.17e}")):
        p = tmp_path / f"t{k}.tum"
        p.write_text("# a comment\n\n" + "\n".join("  ".join(fmt(float(v)) for v in r) for r in vals) + "\n")
        numbers, tokens, _ = files._rows(p, None)
        slow = files._matrix(p, numbers, tokens, 8, "TUM")
        got = files._fast_matrix(p, 8)
        assert got is not None
        assert np.array_equal(got[0], numbers) and slow.tobytes() == got[1].tobytes()


@pytest.mark.parametrize("second, words", [("1 2 3 4 5 6 7 # x", "columns"), ("1 2 3 4 5 6 7", "columns"),
                                           ("1 2 3 4 5 6 7 x", "not a number")])
def test_irregular_files_are_refused_naming_the_line(tmp_path, second, words):
    p = tmp_path / "bad.tum"
    p.write_text("0 0 0 0 0 0 0 1\n" + second + "\n")
    assert files._fast_matrix(p, 8) is None
    with pytest.raises(DataError, match=words) as err:
        files.read_tum(p)
    assert "2" in str(err.value)  # the line
