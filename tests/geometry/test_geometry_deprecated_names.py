"""Renamed geometry helpers (`*_from_*` rule): the old names still work for one release, with a warning."""

import numpy as np
import pytest

import robocal.geometry as g

RENAMED = [
    ("rotx", lambda f: f(0.3), lambda: g.matrix_from_angle("x", 0.3)),
    ("roty", lambda f: f(0.3), lambda: g.matrix_from_angle("y", 0.3)),
    ("rotz", lambda f: f(0.3), lambda: g.matrix_from_angle("z", 0.3)),
    ("translation_transform", lambda f: f([1.0, 2.0, 3.0]), lambda: g.transform_from_translation([1.0, 2.0, 3.0])),
    ("rotation_of", lambda f: f(np.eye(4)), lambda: g.rotation_from_transform(np.eye(4))),
    ("translation_of", lambda f: f(np.eye(4)), lambda: g.translation_from_transform(np.eye(4))),
    ("householder_matrix", lambda f: f([0.0, 0.0, 1.0]), lambda: g.householder_from_normal([0.0, 0.0, 1.0])),
    ("reflection_transform", lambda f: f([0.0, 0.0, 1.0], 0.5), lambda: g.reflection_from_plane([0.0, 0.0, 1.0], 0.5)),
]


@pytest.mark.parametrize("old, call_old, call_new", RENAMED, ids=[r[0] for r in RENAMED])
def test_old_name_warns_and_agrees(old, call_old, call_new):
    with pytest.warns(DeprecationWarning, match=f"{old} is deprecated.*robocal 0.3"):
        got = call_old(getattr(g, old))
    np.testing.assert_array_equal(got, call_new())


def test_matrix_from_angle_is_active_right_handed():
    np.testing.assert_allclose(g.matrix_from_angle("z", np.pi / 2) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    assert g.matrix_from_angle("x", np.zeros((4, 2))).shape == (4, 2, 3, 3)
    with pytest.raises(ValueError, match="axis"):
        g.matrix_from_angle("w", 0.1)
