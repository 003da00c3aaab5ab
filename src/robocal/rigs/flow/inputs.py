"""The flow workflow's ``load_input`` step, apart from the rig's numerical modules: a usage slip
(``robocal flow calibrate`` with neither a run.yaml nor ``--bag``) is a one-line error before numba, cv2 or
SciPy are imported (tests/cli/test_rig_imports.py)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from robocal.errors import InputError

if TYPE_CHECKING:
    from robocal.rigs.flow.log import RunSpec

__all__ = ["load_input"]


def load_input(path=None, *, bag=None, map=None, **_) -> "RunSpec":
    """The ``load_input`` step: ``run.yaml`` read and checked, or, with ``bag``, a recording through its topic
    map (:func:`robocal.rigs.flow.bag.load_bag_run`): the same records and reference, in memory."""
    if bag is not None:
        if path is not None:
            raise InputError(f"give a run.yaml or --bag, not both (got {path} and --bag {bag})")
        from robocal.rigs.flow.bag import load_bag_run

        return load_bag_run(bag, map)
    if path is None:
        raise InputError("give a run.yaml, or a recording with --bag FILE --map topics.yaml")
    from robocal.rigs.flow.log import load_run

    return load_run(path)
