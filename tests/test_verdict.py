"""The reproductions' shared verdict table and portability check."""
import pytest

from replay.reproduce.verdict import Claim, check_portable, result_rows, verdict_table


def test_verdict_table_counts_and_links():
    claims = [Claim("IGWO-STCPF beats PF", "4.14 ± 0.29", "3.1", "deviation explained", "#table-5",
                    cause="the bounds of PSO"),
              Claim("CKF 2.1 m", "2.08 ± 0.05", "2.1", "reproduced", "#table-2")]
    t = verdict_table(claims)
    assert "[table-5](#table-5)" in t and "**deviation explained**: the bounds of PSO" in t
    assert t.endswith("1 reproduced, 1 deviation explained, 0 not reproduced (of 2 claims).")
    with pytest.raises(ValueError):
        Claim("x", "1", "1", "deviation explained", "#a")  # no cause
    with pytest.raises(ValueError):
        Claim("x", "1", "1", "maybe", "#a")


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
