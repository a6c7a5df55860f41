"""The reproductions' shared leaderboard rows and the portability check of documents."""
import pytest

from replay.reproduce.tables import result_rows
from replay.util.portable import check_portable


def test_result_rows_show_median_lost_and_diverged():
    row = {"label": "pf", "pos_rmse": 14.7522, "pos_rmse_ci95": 18.5296, "pos_rmse_median": 3.4378,
           "lost": 2, "lost_share": 0.8, "runs": 20, "diverged": 0}
    t = result_rows([row])
    assert "| pf | 14.752 ± 18.530 | 3.438 | 2/20* | 0/20 |" in t


def test_machine_paths_refused(tmp_path):
    from pathlib import Path

    with pytest.raises(ValueError, match="machine-specific"):
        check_portable(f"see {Path.home()}/data", "doc")
    check_portable("see ../shared/datasets/bohai", "doc")
