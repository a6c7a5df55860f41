"""replay.outputs.plots: absolute errors per run, the stacked median-and-band panels (synthetic inputs, fast)."""

import numpy as np

from replay.outputs.plots import abs_errors, band_panels


def test_band_panels_median_band_units_and_last_times():
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((6, 30)), rng.standard_normal((6, 30))
    fig = band_panels(np.arange(31.0), [("p̂ depth", "m", a), ("q̂ north", "m/step", b)], "#123456", "AUKF", "6 runs")
    assert [ax.get_ylabel() for ax in fig.axes] == ["p̂ depth (m)", "q̂ north (m/step)"]
    assert fig.axes[-1].get_xlabel() == "t (s)" and fig._suptitle.get_text() == "6 runs"
    line = next(ln for ln in fig.axes[1].get_lines() if ln.get_label() == "AUKF")
    assert np.allclose(line.get_xdata(), np.arange(1.0, 31.0))  # the last 30 times
    assert np.allclose(line.get_ydata(), np.median(b, axis=0)) and line.get_color() == "#123456"
    band = [c for c in fig.axes[1].collections if c.get_gid() == "AUKF"]
    assert len(band) == 1
    ys = band[0].get_paths()[0].vertices[:, 1]
    lo, hi = np.percentile(b, (5, 95), axis=0)
    assert np.isclose(ys.min(), lo.min()) and np.isclose(ys.max(), hi.max())


def test_abs_errors_per_quantity_and_column():
    runs = [{"position": np.array([[1.0, -2.0], [-3.0, 4.0]]), "vx": np.array([-0.5, 0.25])}] * 3
    e = abs_errors(runs, [["east", "east error", "m", "position", 1], ["vx", "vx error", "m/s", "vx"]])
    assert list(e) == ["east", "vx"] and e["east"].shape == (3, 2)
    assert np.array_equal(e["east"][2], [2.0, 4.0]) and np.array_equal(e["vx"][0], [0.5, 0.25])
