"""dynid.fleet: many recordings of many robots identified on a Dask cluster, drift tests and the fleet report.

>>> from dynid.fleet import identify_fleet
>>> result = identify_fleet("ur5", "recordings/**/*.csv", friction="linear", gmm="off")
>>> print(result.summary())
>>> result.write("fleet/")

:mod:`~dynid.fleet.recordings` finds the recordings and their robot and time, :mod:`~dynid.fleet.core`
identifies them (one Dask task each), :mod:`~dynid.fleet.drift` tests the parameters for change over
time and against the fleet, :mod:`~dynid.fleet.report` draws the HTML page, :mod:`~dynid.fleet.simulated` makes a fleet with a known truth.  Submodules are imported on
first use.
"""

from __future__ import annotations

from dynid._lazy import lazy_exports

_EXPORTS = {
    "FleetResult": "core",
    "FleetSettings": "core",
    "identify_fleet": "core",
    "Recording": "recordings",
    "find_recordings": "recordings",
    "DriftResult": "drift",
    "detect_drift": "drift",
    "write_fleet_report": "report",
    "Change": "simulated",
    "simulate_fleet": "simulated",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
