"""Geodetic coordinates to local metres, shared by the adapters.

Both the ``bohai-csv`` and the ``bags`` adapter project WGS 84 latitude and
longitude to the UTM zone of the data (:func:`utm_epsg`) and express positions
relative to an origin; :func:`enu_to_geodetic` is the inverse used by the
exports.
"""

from __future__ import annotations

import numpy as np


def utm_epsg(lat, lon) -> int:
    """EPSG code of the WGS 84 UTM zone of the data (median longitude, latitude sign)."""
    zone = int(np.floor((np.median(lon) + 180.0) / 6.0)) % 60 + 1
    return (32600 if np.median(lat) >= 0 else 32700) + zone


def plausible_latlon(lat, lon):
    """True where lat/lon is finite, on the globe and not the 0/0 of a receiver without a fix."""
    ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
    return ok & ~((lat == 0) & (lon == 0))


def project(to_utm, lat, lon, ok):
    """(n, 2) easting/northing by the transformer ``to_utm`` where ``ok``, NaN elsewhere."""
    out = np.full((len(lat), 2), np.nan)
    e, nn = to_utm.transform(lon[ok], lat[ok])
    out[ok, 0], out[ok, 1] = e, nn
    return out


class Geo:
    """lat/lon/alt <-> local ENU via the UTM zone of the first mapped fix topic."""

    def __init__(self, lat, lon, alt, ok):
        # lazy: start-up, every adapter imports this module: pyproj measured ~210 ms
        import pyproj  # noqa: PLC0415

        self.epsg = utm_epsg(lat[ok], lon[ok])
        self._fwd = pyproj.Transformer.from_crs("EPSG:4326", f"EPSG:{self.epsg}", always_xy=True)
        first = int(np.argmax(ok))
        e, n = self._fwd.transform(lon[first], lat[first])
        self.origin = np.array([e, n, alt[first]], float)

    def forward(self, lat, lon, alt, ok):
        out = np.full((len(lat), 3), np.nan)
        if ok.any():
            e, n = self._fwd.transform(lon[ok], lat[ok])
            out[ok] = np.column_stack([e, n, alt[ok]]) - self.origin
        return out

    def meta(self) -> dict:
        return {
            "crs": f"EPSG:{self.epsg}",
            "epsg": self.epsg,
            "origin": [float(self.origin[0]), float(self.origin[1])],
            "origin_alt": float(self.origin[2]),
        }


def enu_to_geodetic(enu, meta):
    """(n, 3) local ENU -> (lat, lon, alt) using ``meta`` crs / origin / origin_alt."""
    # lazy: start-up, every adapter imports this module: pyproj measured ~210 ms
    import pyproj  # noqa: PLC0415

    inv = pyproj.Transformer.from_crs(meta["crs"], "EPSG:4326", always_xy=True)
    enu = np.asarray(enu, float)
    lon, lat = inv.transform(enu[:, 0] + meta["origin"][0], enu[:, 1] + meta["origin"][1])
    up = enu[:, 2] if enu.shape[1] > 2 else np.zeros(len(enu))
    return np.asarray(lat), np.asarray(lon), up + meta.get("origin_alt", 0.0)
