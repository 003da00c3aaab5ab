"""Kinematic trees: FK against D-H chains, paths, mimic joints, Jacobians vs finite differences."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes

from robocal.errors import InputError, NonFiniteError, ShapeError
from robocal.geometry import matrix_from_angle, invert_transform, matrix_from_rotvec, transform_from
from robocal.kinematics import DHChain, Joint, KinematicTree, Mimic

SETTINGS = settings(max_examples=30, deadline=None)
CAM = "CameraBottom_optical_frame"


def T(R=np.eye(3), t=(0, 0, 0)):
    return transform_from(R, t)


@pytest.fixture
def nao(nao_path):
    return KinematicTree.from_urdf(nao_path)


def test_tree_fk_equals_seed000_dh_chain_built_by_hand():
    # Seed 000 Table 1 as named joints: origin Rx(alpha) Tx(a) Tz(d), axis z, theta as the offset.
    d1, d2 = 0.3, 0.1
    tree = KinematicTree([
        Joint("S1", "base", "link1", T(matrix_from_angle("x", np.pi), (0, 0, 0)) @ T(t=(0, 0, d1)), offset=-np.pi / 2),
        Joint("S2", "link1", "link2", T(matrix_from_angle("x", -np.pi / 2))),
        Joint("E", "link2", "laser", T(matrix_from_angle("x", np.pi / 2)) @ T(t=(0, 0, d2)), type="fixed"),
    ])
    chain = DHChain.from_table([[np.pi, 0, -np.pi / 2, d1], [-np.pi / 2, 0, 0, 0], [np.pi / 2, 0, 0, d2]],
                               joint_types="RRF")
    rng = np.random.default_rng(10)
    q = rng.uniform(-np.pi, np.pi, (100, 2))
    assert np.abs(tree.fk(q)["laser"] - chain.fk(q)).max() < 1e-14
    assert np.abs(tree.fk({"S1": q[:, 0], "S2": q[:, 1]})["laser"] - chain.fk(q)).max() < 1e-14
    assert np.abs(tree.jacobian(q, "base", "laser") - chain.jacobian(q)).max() < 1e-14


def test_prismatic_tree_joint():
    axis = np.array([1.0, 2.0, 2.0]) / 3
    tree = KinematicTree([Joint("slide", "a", "b", T(matrix_from_rotvec([0.1, 0.2, 0.3]), (1, 0, 0)), axis * 3,
                                "prismatic", offset=0.02)])
    T0, T1 = tree.fk([0.0])["b"], tree.fk([0.5])["b"]
    R0 = matrix_from_rotvec([0.1, 0.2, 0.3])
    assert np.abs(T0[:3, 3] - ([1, 0, 0] + 0.02 * R0 @ axis)).max() < 1e-15
    assert np.abs(T1[:3, 3] - T0[:3, 3] - 0.5 * R0 @ axis).max() < 1e-15
    assert np.abs(T1[:3, :3] - R0).max() < 1e-15


def test_nao_structure(nao):
    assert nao.root == "torso"
    assert "RHipYawPitch" not in nao.joint_names  # it mimics LHipYawPitch
    assert nao.n_joints == 2 + 6 + 5
    assert [j.name for j in nao.chain("torso", "l_sole")] == [
        "LHipYawPitch", "LHipRoll", "LHipPitch", "LKneePitch", "LAnklePitch", "LAnkleRoll", "LSole"]
    assert nao.chain("Lthigh", "Lthigh") == []
    with pytest.raises(InputError, match="not an ancestor"):
        nao.chain("l_sole", "torso")
    # At q = 0 the sole is below the hip by thigh + tibia + foot height (the NAO H25 link lengths).
    sole = nao.fk(np.zeros(nao.n_joints))["l_sole"]
    assert np.abs(sole[:3, 3] - [0, 0.05, -0.085 - 0.1 - 0.1029 - 0.04519]).max() < 1e-15


def test_transform_is_relative_pose(nao):
    rng = np.random.default_rng(11)
    q = rng.uniform(-0.5, 0.5, (7, nao.n_joints))
    poses = nao.fk(q)
    for target, source in [(CAM, "l_sole"), ("r_sole", "Head"), ("torso", "r_sole"), ("Lhip", "torso"),
                           ("Ltibia", "Ltibia"), ("l_sole", "Lthigh")]:
        expected = invert_transform(poses[target]) @ poses[source]
        assert np.abs(nao.transform(q, target, source) - expected).max() < 1e-14


def test_mimic_joint_follows_its_leader(nao):
    # The same tree with RHipYawPitch free must agree when it is given the leader's value.
    free = KinematicTree([j if j.name != "RHipYawPitch" else Joint(j.name, j.parent, j.child, j.origin, j.axis,
                                                                     j.type, j.limits)
                          for j in nao.joints])
    rng = np.random.default_rng(12)
    qd = {n: rng.uniform(-0.5, 0.5, 5) for n in nao.joint_names}
    mimicked = nao.fk(qd)["r_sole"]
    assert np.abs(free.fk({**qd, "RHipYawPitch": qd["LHipYawPitch"]})["r_sole"] - mimicked).max() < 1e-15
    assert np.abs(free.fk({**qd, "RHipYawPitch": qd["LHipYawPitch"] + 0.1})["r_sole"] - mimicked).max() > 1e-3
    # The leader's offset moves both legs (one motor, one offset).
    shifted = nao.with_offsets({"LHipYawPitch": 0.05})
    assert np.abs(shifted.fk(qd)["r_sole"] - nao.fk({**qd, "LHipYawPitch": qd["LHipYawPitch"] + 0.05})["r_sole"]
                  ).max() < 1e-15
    # with_mimic(None) frees the follower; with_mimic(f, l) ties it again
    untied = nao.with_mimic("RHipYawPitch", None)
    assert "RHipYawPitch" in untied.joint_names and untied.joint("RHipYawPitch").mimic is None
    assert np.abs(untied.fk({**qd, "RHipYawPitch": qd["LHipYawPitch"]})["r_sole"] - mimicked).max() < 1e-15
    retied = untied.with_mimic("RHipYawPitch", "LHipYawPitch")
    assert retied.joint_names == nao.joint_names
    assert np.abs(retied.fk(qd)["r_sole"] - mimicked).max() < 1e-15
    with pytest.raises(InputError, match="independent movable joint"):
        untied.with_mimic("RHipYawPitch", "RHipYawPitch")
    with pytest.raises(InputError, match="unknown joint"):
        untied.with_mimic("RHipYawPitch", "nope")
    # multiplier and offset
    tree = KinematicTree([Joint("a", "base", "l1"), Joint("b", "base", "l2", mimic=Mimic("a", -2.0, 0.3))])
    assert np.abs(tree.fk([0.4])["l2"][:3, :3] - tree.fk([-0.5])["l1"][:3, :3]).max() < 1e-15


@pytest.mark.parametrize("target,source", [("torso", "l_sole"), (CAM, "r_sole"), ("r_sole", "Head"),
                                           ("Lfoot", "Rfoot")])
def test_jacobian_matches_finite_differences(nao, fd, target, source):
    rng = np.random.default_rng(13)
    q = rng.uniform(-0.6, 0.6, nao.n_joints)
    J = nao.jacobian(q, target, source)
    num = fd(lambda x: nao.transform(x, target, source), q)
    assert J.shape == (6, nao.n_joints)
    assert np.abs(num).max() > 0.05  # the comparison is not between zeros
    assert np.abs(J - num).max() < 1e-8, np.abs(J - num).max()


def test_offset_jacobian_matches_finite_differences(nao, fd):
    rng = np.random.default_rng(14)
    nao = nao.with_offsets(rng.normal(scale=0.01, size=nao.n_joints))
    q = rng.uniform(-0.6, 0.6, (3, nao.n_joints))
    J = nao.offset_jacobian(q, CAM, "r_sole")
    for k in range(3):
        num = fd(lambda off: nao.with_offsets(off).transform(q[k], CAM, "r_sole"), nao.offsets)
        assert np.abs(J[k] - num).max() < 1e-8
    # the tied hip offset moves the right foot although only LHipYawPitch is a parameter
    assert np.abs(J[:, :, nao.joint_names.index("LHipYawPitch")]).max() > 0.01


def test_origin_jacobian_matches_finite_differences(nao, fd):
    rng = np.random.default_rng(15)
    joints = ["CameraBottom", "LKneePitch", "HeadYaw", "RSole"]
    q = rng.uniform(-0.6, 0.6, nao.n_joints)
    J = nao.origin_jacobian(q, CAM, "l_sole", joints)
    names = nao.origin_param_names(joints)
    assert J.shape == (6, 24) and len(names) == 24 and names[3] == "CameraBottom.roll"

    def pose(x):
        tree = nao
        for k, j in enumerate(joints):
            tree = tree.with_origin(j, x[6 * k: 6 * k + 6])
        return tree.transform(q, CAM, "l_sole")

    x0 = np.concatenate([nao.origin_params(j) for j in joints])
    num = fd(pose, x0)
    assert np.abs(J - num).max() < 1e-8, np.abs(J - num).max()
    assert np.all(J[:, 18:] == 0.0)  # RSole is off the camera -> left-foot path


@SETTINGS
@given(batch=array_shapes(min_dims=0, max_dims=3, min_side=1, max_side=3), seed=st.integers(0, 2**31))
def test_vectorised_dict_values_broadcast(nao_path, batch, seed):
    nao = KinematicTree.from_urdf(nao_path)
    rng = np.random.default_rng(seed)
    # Per-joint values of different broadcastable shapes (some axes 1, some dropped), scalars for the rest.
    q = {}
    for n in ["HeadPitch", "LKneePitch", "LHipYawPitch"]:
        shape = tuple(1 if rng.random() < 0.4 else b for b in batch)[rng.integers(0, len(batch) + 1):]
        q[n] = rng.uniform(-0.5, 0.5, shape)
    q.update({n: float(rng.uniform(-0.5, 0.5)) for n in nao.joint_names if n not in q})
    expected = np.broadcast_shapes(*[np.shape(v) for v in q.values()])
    poses = nao.fk(q)
    assert all(P.shape == expected + (4, 4) for P in poses.values())
    J = nao.jacobian(q, CAM, "l_sole")
    assert J.shape == expected + (6, nao.n_joints)
    assert nao.transform(q, CAM, "r_sole").shape == expected + (4, 4)
    arr = np.stack(np.broadcast_arrays(*[np.asarray(q[n], float) for n in nao.joint_names]), axis=-1)
    assert np.abs(nao.fk(arr)["l_sole"] - poses["l_sole"]).max() < 1e-15
    for idx in np.ndindex(*expected):
        assert np.abs(nao.jacobian(arr[idx], CAM, "l_sole") - J[idx]).max() < 1e-14
        assert np.abs(nao.fk(arr[idx])[CAM] - poses[CAM][idx]).max() < 1e-15


def test_fold_offsets_keeps_fk(nao):
    rng = np.random.default_rng(16)
    off = nao.with_offsets(rng.normal(scale=0.05, size=nao.n_joints)).with_offsets({"RHipYawPitch": 0.02})
    folded = off.fold_offsets()
    assert np.all(folded.offsets == 0) and all(j.offset == 0 for j in folded.joints)
    q = rng.uniform(-0.5, 0.5, (9, nao.n_joints))
    a, b = off.fk(q), folded.fk(q)
    assert max(np.abs(a[k] - b[k]).max() for k in a) < 1e-14
    assert max(np.abs(a[k] - nao.fk(q)[k]).max() for k in a) > 1e-2


def test_with_origin_and_limits(nao):
    x = nao.origin_params("CameraBottom")
    assert np.allclose(x, [0.05071, 0, 0.01774, 0, 0.6929, 0])
    moved = nao.with_origin("CameraBottom", x + [0, 0, 0, 0.01, 0, 0])
    assert np.allclose(moved.origin_params("CameraBottom"), x + [0, 0, 0, 0.01, 0, 0])
    assert np.abs(nao.with_origin("CameraBottom", nao.joint("CameraBottom").origin).origin_params("CameraBottom") - x
                  ).max() < 1e-15
    q = np.zeros((2, nao.n_joints))
    q[1, nao.joint_names.index("LKneePitch")] = -0.5  # below its lower limit -0.092
    assert nao.within_limits(q).tolist() == [True, False]
    with pytest.raises(ShapeError, match=r"origin must have shape \(4, 4\) or \(6,\)"):
        nao.with_origin("CameraBottom", [0, 0, 0])


def test_bad_joint_values_raise_named_errors(nao):
    q = {n: 0.0 for n in nao.joint_names}
    with pytest.raises(InputError, match="unknown joint 'Knee'"):
        nao.fk({**q, "Knee": 0.1})
    with pytest.raises(InputError, match=r"missing joints \['HeadYaw'\]"):
        nao.fk({k: v for k, v in q.items() if k != "HeadYaw"})
    assert np.all(nao.fk({"HeadYaw": 0.1}, default=0.0)["Head"] == nao.fk({**q, "HeadYaw": 0.1})["Head"])
    with pytest.raises(InputError, match="mimic of 'LHipYawPitch'"):
        nao.fk({**q, "RHipYawPitch": 0.1})
    with pytest.raises(InputError, match="fixed"):
        nao.fk({**q, "CameraBottom": 0.1})
    with pytest.raises(NonFiniteError, match=r"q\['LKneePitch'\] contains NaN"):
        nao.fk({**q, "LKneePitch": [0.1, np.nan]})
    with pytest.raises(ShapeError, match="broadcastable"):
        nao.fk({**q, "LKneePitch": [0.1, 0.2], "HeadYaw": [1, 2, 3]})
    with pytest.raises(ShapeError, match=r"q must have shape \(\.\.\., 13\)"):
        nao.fk(np.zeros((4, 12)))
    with pytest.raises(NonFiniteError):
        nao.jacobian(np.full(13, np.inf), "torso", "l_sole")
    with pytest.raises(InputError, match="unknown link 'foot'"):
        nao.transform(q, "torso", "foot")
    with pytest.raises(InputError, match="unknown joint"):
        nao.origin_jacobian(q, "torso", "l_sole", ["nope"])


def test_bad_trees_raise_named_errors():
    with pytest.raises(InputError, match="two parent joints"):
        KinematicTree([Joint("a", "x", "y"), Joint("b", "z", "y")])
    with pytest.raises(InputError, match="several root links"):
        KinematicTree([Joint("a", "x", "y"), Joint("b", "z", "w")])
    with pytest.raises(InputError, match="cycle"):
        KinematicTree([Joint("a", "x", "y"), Joint("b", "y", "x")])
    with pytest.raises(InputError, match="not connected"):
        KinematicTree([Joint("a", "r", "x"), Joint("b", "y", "z"), Joint("c", "z", "y")])
    with pytest.raises(InputError, match="used twice"):
        KinematicTree([Joint("a", "x", "y"), Joint("a", "y", "z")])
    with pytest.raises(InputError, match="mimics 'c'"):
        KinematicTree([Joint("a", "x", "y"), Joint("b", "y", "z", mimic=Mimic("c"))])
    with pytest.raises(InputError, match="axis must be a non-zero"):
        Joint("a", "x", "y", axis=[0, 0, 0])
    with pytest.raises(InputError, match="fixed joint 'a' cannot have an offset"):
        Joint("a", "x", "y", type="fixed", offset=0.1)
    with pytest.raises(InputError, match="origin"):
        Joint("a", "x", "y", origin=np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(InputError, match="root=<link name>"):
        KinematicTree([])
    assert KinematicTree([], root="base").fk(np.zeros(0))["base"].shape == (4, 4)
