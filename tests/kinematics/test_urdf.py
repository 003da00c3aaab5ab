"""URDF loading and writing: conventions, round trips, kept extras, malformed files."""

import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocal.errors import FileFormatError
from robocal.geometry import matrix_from_angle, matrix_from_rotvec, transform_from
from robocal.kinematics import DHChain, Joint, KinematicTree, Mimic, tree_from_urdf

CAM = "CameraBottom_optical_frame"


def urdf(joints_xml: str, links=("a", "b", "c")) -> str:
    body = "".join(f'<link name="{n}"/>' for n in links)
    return f'<robot name="t">{body}{joints_xml}</robot>'


def max_fk_diff(t1, t2, q):
    a, b = t1.fk(q), t2.fk(q)
    assert set(a) == set(b)
    return max(np.abs(a[k] - b[k]).max() for k in a)


def test_origin_rpy_is_fixed_axis_roll_pitch_yaw():
    r, p, y = 0.3, -0.7, 1.9
    tree = KinematicTree.from_urdf(urdf(
        f'<joint name="j" type="fixed"><parent link="a"/><child link="b"/>'
        f'<origin xyz="0.1 -0.2 0.3" rpy="{r} {p} {y}"/></joint>', links=("a", "b")))
    expected = transform_from(matrix_from_angle("z", y) @ matrix_from_angle("y", p) @ matrix_from_angle("x", r), [0.1, -0.2, 0.3])
    assert np.abs(tree.joint("j").origin - expected).max() < 1e-15


def test_defaults_types_limits_and_mimic():
    tree = KinematicTree.from_urdf(urdf(
        '<joint name="j1" type="continuous"><parent link="a"/><child link="b"/>'
        '<limit effort="1" velocity="1"/></joint>'
        '<joint name="j2" type="prismatic"><parent link="b"/><child link="c"/><axis xyz="0 0 2"/>'
        '<limit lower="-0.1" upper="0.2" effort="1" velocity="1"/>'
        '<mimic joint="j1" multiplier="0.5" offset="0.01"/></joint>'))
    j1, j2 = tree.joint("j1"), tree.joint("j2")
    assert j1.type == "continuous" and j1.limits is None
    assert np.all(j1.axis == [1, 0, 0])  # URDF's default axis
    assert np.all(j1.origin == np.eye(4))
    assert j2.type == "prismatic" and j2.limits == (-0.1, 0.2) and np.all(j2.axis == [0, 0, 1])
    assert j2.mimic == Mimic("j1", 0.5, 0.01)
    assert tree.joint_names == ("j1",)
    # j2 = 0.5 * 0.4 + 0.01 along z
    assert abs(tree.transform([0.4], "b", "c")[2, 3] - 0.21) < 1e-15


def test_round_trip_keeps_kinematics_and_extras(nao_path, tmp_path):
    nao = KinematicTree.from_urdf(nao_path)
    assert max_fk_diff(nao, tree_from_urdf(nao_path.read_text()), np.zeros(nao.n_joints)) == 0.0
    out = tmp_path / "nao_out.urdf"
    text = nao.to_urdf(out)
    assert out.read_text() == text
    # the project's atomic writer: readable by others like any new file (was mkstemp's 0600)
    assert out.stat().st_mode & 0o044 == 0o044 or os.umask(os.umask(0)) & 0o044
    again = KinematicTree.from_urdf(out)
    rng = np.random.default_rng(20)
    q = rng.uniform(-1, 1, (10, nao.n_joints))
    assert max_fk_diff(nao, again, q) < 1e-15
    assert again.joint_names == nao.joint_names
    for j in nao.joints:
        k = again.joint(j.name)
        assert (k.type, k.parent, k.child, k.limits, k.mimic) == (j.type, j.parent, j.child, j.limits, j.mimic)
    # visuals, inertials, transmissions and the limits' effort/velocity survive
    for tag in ('<mass value="1.05"', '<box size="0.1 0.14 0.2"', "SimpleTransmission", 'effort="1.5"'):
        assert tag in text


def test_calibrated_urdf_folds_offsets(nao_path):
    nao = KinematicTree.from_urdf(nao_path)
    rng = np.random.default_rng(21)
    calibrated = nao.with_offsets(rng.normal(scale=0.01, size=nao.n_joints))
    loaded = KinematicTree.from_urdf(calibrated.to_urdf())
    q = rng.uniform(-1, 1, (10, nao.n_joints))
    assert np.all(loaded.offsets == 0.0)
    assert max_fk_diff(calibrated, loaded, q) < 1e-14
    assert max_fk_diff(nao, loaded, q) > 1e-3
    with pytest.raises(FileFormatError, match="non-zero offsets"):
        calibrated.to_urdf(fold_offsets=False)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 8))
def test_random_tree_round_trip(seed, n):
    rng = np.random.default_rng(seed)
    joints, links = [], ["root"]
    for k in range(n):
        kind = ["revolute", "continuous", "prismatic", "fixed"][rng.integers(4)]
        origin = transform_from(matrix_from_rotvec(rng.normal(size=3) * 2), rng.normal(size=3))
        limits = tuple(np.sort(rng.uniform(-2, 2, 2))) if kind in ("revolute", "prismatic") else None
        mimic = None
        movable = [j.name for j in joints if j.type != "fixed" and j.mimic is None]
        if kind != "fixed" and movable and rng.random() < 0.3:
            mimic = Mimic(movable[rng.integers(len(movable))], rng.normal(), rng.normal())
        joints.append(Joint(f"j{k}", links[rng.integers(len(links))], f"l{k}", origin, rng.normal(size=3), kind,
                            limits, 0.0 if kind == "fixed" else rng.normal(scale=0.1), mimic))
        links.append(f"l{k}")
    tree = KinematicTree(joints, name="random")
    again = KinematicTree.from_urdf(tree.to_urdf())
    q = rng.uniform(-1, 1, (5, tree.n_joints))
    assert max_fk_diff(tree, again, q) < 1e-12
    assert again.links == tree.links and again.joint_names == tree.joint_names


def test_dh_chain_to_urdf_round_trip():
    rng = np.random.default_rng(22)
    chain = DHChain.from_table(rng.uniform(-1, 1, (5, 4)), convention="standard", joint_types="RPRFR")
    tree = KinematicTree.from_urdf(chain.to_tree().to_urdf())
    q = rng.uniform(-1, 1, (6, chain.dof))
    assert np.abs(tree.fk(q)["tool"] - chain.fk(q)).max() < 1e-13


J_OK = '<parent link="a"/><child link="b"/>'


@pytest.mark.parametrize("text,match", [
    ("<robot><link name='a'/>", "not well-formed XML"),
    ("<model name='x'/>", "root element must be <robot>, got <model>"),
    (urdf("", links=()), "has no <link>"),
    (urdf("<joint type='fixed'>" + J_OK + "</joint>"), r"<joint> #1 has no name"),
    (urdf("<joint name='knee' type='floating'>" + J_OK + "</joint>"), "joint 'knee': type 'floating' is not supported"),
    (urdf("<joint name='knee' type='revolute'><child link='b'/></joint>"), r"joint 'knee': missing <parent link=\.\.\.>"),
    (urdf("<joint name='knee' type='revolute'><parent link='x'/><child link='b'/></joint>"),
     r"joint 'knee': <parent link='x'> names no <link>"),
    (urdf("<joint name='knee' type='revolute'>" + J_OK + "<origin xyz='0 0'/></joint>"),
     r"joint 'knee': <origin xyz> must be 3 finite numbers, got '0 0'"),
    (urdf("<joint name='knee' type='revolute'>" + J_OK + "<origin rpy='a b c'/></joint>"),
     r"joint 'knee': <origin rpy> must be 3 numbers"),
    (urdf("<joint name='knee' type='revolute'>" + J_OK + "<origin xyz='0 nan 0'/></joint>"),
     r"<origin xyz> must be 3 finite numbers"),
    (urdf("<joint name='knee' type='revolute'>" + J_OK + "<axis xyz='0 0 0'/></joint>"),
     r"joint 'knee': <axis xyz> must not be zero"),
    (urdf("<joint name='knee' type='revolute'>" + J_OK + "<limit lower='1' upper='-1'/></joint>"),
     r"joint 'knee': <limit> lower 1 > upper -1"),
    (urdf("<joint name='knee' type='revolute'>" + J_OK + "<mimic/></joint>"), r"joint 'knee': <mimic> needs attribute 'joint'"),
    (urdf("<joint name='knee' type='revolute'>" + J_OK + "<mimic joint='hip'/></joint>"), r"mimics 'hip'"),
    (urdf("<joint name='k1' type='fixed'>" + J_OK + "</joint><joint name='k2' type='fixed'>"
          "<parent link='c'/><child link='b'/></joint>"), "two parent joints"),
    (urdf("<joint name='k1' type='fixed'>" + J_OK + "</joint>"), r"<link> \['c'\] not connected"),
    (urdf("", links=("a", "a")), r"<link> names used twice: \['a'\]"),
])
def test_malformed_urdf_names_the_element(text, match):
    with pytest.raises(FileFormatError, match=match) as info:
        KinematicTree.from_urdf(text)
    assert str(info.value).startswith("<urdf string>: ")


def test_missing_file_is_a_file_format_error(tmp_path):
    with pytest.raises(FileFormatError, match="cannot read URDF") as info:
        KinematicTree.from_urdf(tmp_path / "nope.urdf")
    assert "nope.urdf" in str(info.value)
