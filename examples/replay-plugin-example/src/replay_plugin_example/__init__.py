"""An example replay plugin (docs/plugins.md).

* filter ``example-filter``: :class:`replay_plugin_example.iekf.IteratedEKF`, an iterated
  extended Kalman filter written over the Monte Carlo run axis;
* task ``example-range-bearing``: :class:`replay_plugin_example.target.RangeBearingTask`,
  a constant-velocity target tracked from range and bearing;
* dataset ``example/range-bearing``: :func:`replay_plugin_example.target.make_frame`,
  its simulator.

They are registered by the entry points of ``pyproject.toml``; without installing,
``--filters replay_plugin_example.iekf:IteratedEKF`` works with ``src/`` on the path.
"""
__version__ = "0.1.0"
