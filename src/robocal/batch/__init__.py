"""Fleets and studies on many cores: ``robocal batch`` and the engine under Monte Carlo studies.

* :mod:`._engine` -- :func:`open_executor`: a Dask ``distributed`` client
  (an embedded ``LocalCluster`` or an existing scheduler), or None for a
  serial run;
* :mod:`._manifest` -- the batch manifest (YAML or CSV): data set ids and
  their calibrate inputs;
* :mod:`._run` -- :func:`run_batch`: each data set calibrated as its own task
  through its rig's workflow steps, written atomically into ``DIR/<id>/``,
  failures as one-line rows, ``resume``;
* :mod:`._fleet` -- :func:`fleet_summary` and the fleet report
  (``fleet.json``, ``fleet.html``);
* :mod:`._simulate_fleet` -- :func:`simulate_fleet`: a simulated fleet with
  planted faults (``robocal <rig> simulate --fleet N``);
* :mod:`._demo` -- :func:`fleet_demo`: ``robocal demo``'s small fleet.

Names are imported from their submodule on first use (PEP 562), so that
``robocal --help`` and the Monte Carlo helper's serial path import no Dask.
See ``docs/batch.md``.
"""

from __future__ import annotations

from robocal._lazy import lazy_exports

_EXPORTS = {
    **dict.fromkeys(("open_executor", "available_cores"), "_engine"),
    **dict.fromkeys(("BatchEntry", "load_manifest"), "_manifest"),
    **dict.fromkeys(("BatchOutcome", "run_batch", "dataset_complete"), "_run"),
    **dict.fromkeys(("fleet_summary", "build_fleet_report", "write_fleet"), "_fleet"),
    **dict.fromkeys(("simulate_fleet", "SimulatedFleet", "scattered_mount", "knocked"), "_simulate_fleet"),
    **dict.fromkeys(("fleet_demo",), "_demo"),
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
