"""A simulated fleet: N robots of one rig, their true parameters scattered, a few with a planted fault.

``robocal <rig> simulate --fleet N --out DIR`` (and :func:`simulate_fleet`)
writes, for every robot ``i``, the rig's simulated input into
``DIR/robot-<i>/`` by the rig's ``fleet`` step (:mod:`robocal.workflow`):
the rig draws the robot's true parameters with the scatter of real robots of
its kind and, for a planted robot, moves one parameter well outside that
scatter (``kind="fault"``: a slipped gear, a knocked camera) or records it
badly (``kind="weak"``). Beside them:

* ``DIR/fleet.yaml`` -- the batch manifest (:mod:`robocal.batch._manifest`;
  ids = folder names), ready for ``robocal batch RIG DIR/fleet.yaml``;
* ``DIR/fleet_truth.json`` -- which robots were planted, and with what.

Seeds: robot ``i`` draws from the ``i+1``-th child of ``rng.spawn`` (one
:class:`numpy.random.SeedSequence` child per robot) and the choice of the
planted robots from the first, so a fleet is reproducible from its seed and
robot ``i``'s data does not depend on how many robots follow it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.errors import InputError

__all__ = ["SimulatedFleet", "simulate_fleet", "planted_counts", "robot_ids", "scattered_mount", "knocked",
           "FLEET_MANIFEST", "FLEET_TRUTH"]

FLEET_MANIFEST = "fleet.yaml"
FLEET_TRUTH = "fleet_truth.json"
#: the share of planted faults in a default fleet ("a few": ~5 %, at least one in a fleet worth judging)
FAULT_SHARE = 0.05
#: the smallest default fleet that also gets one weak recording
WEAK_FROM = 8


def planted_counts(n: int) -> tuple[int, int]:
    """The default ``(faults, weak recordings)`` of a fleet of ``n``.

    ~5 % faults, at least one once the fleet report judges robots
    (:data:`robocal.batch._fleet.MIN_FLEET` of them); one weak recording
    from :data:`WEAK_FROM` robots on.
    """
    from robocal.batch._fleet import MIN_FLEET

    faults = 0 if n < MIN_FLEET else max(1, int(round(FAULT_SHARE * n)))
    return faults, (1 if n >= WEAK_FROM else 0)


def scattered_mount(T, rng: np.random.Generator, mm: float, deg: float, *, own_axes: bool = False) -> np.ndarray:
    """A copy of the mount ``T`` (4x4, m) as one robot of a fleet has it: turned by ``N(0, deg)`` [deg] about
    each axis, then shifted by ``N(0, mm)`` [mm] along each (a bracket's tolerances).

    ``own_axes``: the turn about the mounted part's own axes (right-multiplied), else about its parent's.
    Draws 3 + 3 normals from ``rng`` in that order (the rigs' fleets are reproducible from their seeds).
    """
    from robocal.geometry import matrix_from_rotvec

    T = np.array(T, dtype=float)
    R = matrix_from_rotvec(np.radians(deg) * rng.standard_normal(3))
    T[:3, :3] = T[:3, :3] @ R if own_axes else R @ T[:3, :3]
    T[:3, 3] += 1e-3 * mm * rng.standard_normal(3)
    return T


def knocked(T, rng: np.random.Generator, deg: float, *, axes: int = 2, own_axes: bool = True):
    """A planted fault: the mount ``T`` (4x4) turned by ``+-deg`` about one of its first ``axes`` axes (drawn,
    then the sign) -- a camera or sensor knocked in its bracket, its origin where it was.

    ``own_axes`` as in :func:`scattered_mount`. Returns ``(T_knocked, shift [deg, signed], axis)``.
    """
    from robocal.geometry import matrix_from_rotvec

    axis = int(rng.integers(axes))
    shift = float(rng.choice([-1.0, 1.0])) * deg
    R = matrix_from_rotvec(np.radians(shift) * np.eye(3)[axis])
    T = np.array(T, dtype=float)
    T[:3, :3] = T[:3, :3] @ R if own_axes else R @ T[:3, :3]
    return T, shift, axis


def robot_ids(n: int) -> list[str]:
    """``robot-000``, ``robot-001``, ... (wider numbers above 1000 robots: they sort as they count)."""
    width = max(3, len(str(n - 1)))
    return [f"robot-{i:0{width}d}" for i in range(n)]


@dataclass
class SimulatedFleet:
    """What :func:`simulate_fleet` wrote.

    Attributes
    ----------
    out_dir : Path
    manifest, truth : Path
        ``fleet.yaml`` and ``fleet_truth.json``.
    ids : list of str
    planted : dict of id -> dict
        The planted robots: ``kind`` (``fault`` or ``weak``) and what the rig
        reported (``parameter``, ``text``, ...).
    """

    out_dir: Path
    manifest: Path
    truth: Path
    ids: list
    planted: dict = field(default_factory=dict)

    def of_kind(self, kind: str) -> list[str]:
        return [i for i, p in self.planted.items() if p["kind"] == kind]

    def summary(self) -> str:
        faults, weak = self.of_kind("fault"), self.of_kind("weak")
        text = f"fleet: {len(self.ids)} simulated robot(s); planted fault(s): {', '.join(faults) or 'none'}"
        if weak:
            text += f"; weak recording(s): {', '.join(weak)}"
        return text + f" ({self.truth.name})"


def simulate_fleet(wf, out_dir, n: int, rng: np.random.Generator, *, faults: int | None = None,
                   weak: int | None = None, progress: bool = False, executor=None, **options) -> SimulatedFleet:
    """Simulate ``n`` robots of rig ``wf`` into ``out_dir/robot-<i>/`` with their manifest and truth.

    Parameters
    ----------
    wf : robocal.workflow.Workflow
        A rig with a ``fleet`` step.
    out_dir : path
        An existing (claimed) folder.
    n : int
        Robots, >= 1.
    rng : numpy.random.Generator
        The fleet's only randomness: spawned once per robot (module docstring).
    faults, weak : int, optional
        Planted faults and weak recordings (default :func:`planted_counts`).
    executor : Dask Client or concurrent.futures executor, optional
        Simulate the robots there (:func:`robocal.batch.open_executor`; the
        workers must see ``out_dir``); the same files as serially.
    **options
        The rig's ``simulate`` options, the same for every robot.
    """
    from robocal.io import atomic_write_text
    from robocal.progress import progress as _progress

    step = wf.step("fleet")
    if step is None:
        raise InputError(f"rig {wf.name!r} declares no fleet step: it cannot simulate a fleet")
    n = int(n)
    d_faults, d_weak = planted_counts(n)
    faults, weak = (d_faults if faults is None else int(faults)), (d_weak if weak is None else int(weak))
    if n < 1 or faults < 0 or weak < 0 or faults + weak > n:
        raise InputError(f"--fleet: {n} robot(s) with {faults} fault(s) and {weak} weak recording(s): "
                         "need n >= 1 and faults + weak <= n")
    out_dir = Path(out_dir)
    ids = robot_ids(n)
    choose, *streams = rng.spawn(n + 1)
    picked = choose.choice(n, size=faults + weak, replace=False) if faults + weak else np.array([], int)
    kinds = {int(i): "fault" for i in picked[:faults]} | {int(i): "weak" for i in picked[faults:]}
    for i in range(n):
        (out_dir / ids[i]).mkdir(parents=True, exist_ok=True)
    if executor is None:
        done = (step(out_dir / ids[i], streams[i], kind=kinds.get(i), progress=False, **options) for i in range(n))
    else:
        extra = {"pure": False} if type(executor).__module__.split(".")[0] == "distributed" else {}
        futures = [executor.submit(step, out_dir / ids[i], streams[i], kind=kinds.get(i), progress=False,
                                   **options, **extra) for i in range(n)]
        done = (f.result() for f in futures)
    planted, datasets = {}, []
    for i, what in enumerate(_progress(done, desc=f"fleet {wf.name}", total=n, enabled=progress)):
        what = what or {}
        if i in kinds:
            planted[ids[i]] = {"kind": kinds[i], **what}
        inputs = [f"{ids[i]}/{name}" for name in wf.simulated_inputs]
        datasets.append({"id": ids[i], **({"input": inputs[0]} if len(inputs) == 1 else {"inputs": inputs})})
    import yaml

    manifest = atomic_write_text(out_dir / FLEET_MANIFEST, (
        f"# robocal {wf.name} simulate --fleet {n}: calibrate with\n"
        f"#   robocal batch {wf.name} {FLEET_MANIFEST} --out <DIR>\n"
        + yaml.safe_dump({"rig": wf.name, "datasets": datasets}, sort_keys=False)))
    doc = {"schema": "robocal.fleet-truth/1", "rig": wf.name, "n_robots": n, "ids": ids,
           "faults": [{"id": i, **{k: v for k, v in p.items() if k != "kind"}} for i, p in planted.items()
                      if p["kind"] == "fault"],
           "weak": [{"id": i, **{k: v for k, v in p.items() if k != "kind"}} for i, p in planted.items()
                    if p["kind"] == "weak"],
           "options": {k: v for k, v in options.items() if isinstance(v, (bool, int, float, str, type(None)))}}
    truth = atomic_write_text(out_dir / FLEET_TRUTH, json.dumps(doc, indent=2, default=_plain) + "\n")
    return SimulatedFleet(out_dir, Path(manifest), Path(truth), ids, dict(sorted(planted.items())))


def _plain(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)
