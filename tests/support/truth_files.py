"""Reading a simulated data set's truth file in tests (``truth.yaml`` as the simulators write it)."""

import numpy as np
import yaml


def truth_pose(path, name: str) -> np.ndarray:
    """The 4 x 4 pose ``name`` of a truth file (``rotation`` 3 x 3, ``translation`` m)."""
    d = yaml.safe_load(open(path, encoding="utf-8"))[name]
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = d["rotation"], d["translation"]
    return T
