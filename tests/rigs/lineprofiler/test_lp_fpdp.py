"""The profiler model and FPDP (seed 004 §2) on simulated data with known truth."""

import numpy as np
import pytest

from robocal.errors import InputError, NotEnoughDataError
from robocal.geometry import apply_transform, invert_transform, transform_from
from robocal.kinematics import DHChain
from robocal.rigs.lineprofiler.fpdp import fpdp_calibrate
from robocal.handeye import transform_error
from robocal.rigs.lineprofiler.model import Block, ProfilerModel, Sphere, default_rig
from robocal.rigs.lineprofiler.simulate import simulate_fpdp

RIG = default_rig()


def test_profiler_sees_sphere_with_occlusion_and_range():
    prof = ProfilerModel(n_points=200, dropout=0.0)
    s = Sphere([0, 0, 0.25], 0.0254)
    xz, _ = prof.measure(np.eye(4), [s], noise=False)
    p = np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]])
    assert np.allclose(np.linalg.norm(p - s.centre, axis=1), s.radius, atol=1e-12)
    # range limits cut it off; a block in front of it occludes it
    assert len(prof.measure(np.eye(4), [Sphere([0, 0, 0.6], 0.0254)], noise=False)[0]) == 0
    wall = Block(transform_from(np.eye(3), [0.5, 0.5, 0.2]), (1.0, 1.0, 0.01))
    xz2, which = prof.measure(np.eye(4), [s, wall], noise=False)
    assert np.all(which == 1)


@pytest.mark.parametrize("noise", [False, True])
def test_fpdp_names_undetermined_component_on_p1r2p3(noise):
    d, tr = simulate_fpdp(RIG, np.random.default_rng(0), noise=noise)
    r = fpdp_calibrate(d.q, d.profiles, RIG.chain, d.sphere_radius)
    assert r.undetermined == ("X.ty", "Q.z")
    assert r.translation_report()["ty"] is None and np.isnan(r.t_std[1])
    assert "rank_deficient" in [w.code for w in r.warnings]
    rot, _ = transform_error(r.X, RIG.X)
    assert rot < (1e-10 if not noise else 0.01)
    assert abs(r.X[0, 3] - RIG.X[0, 3]) < (1e-10 if not noise else 1e-3)
    assert np.all(np.isfinite(r.t_std[[0, 2]]))


def test_fpdp_full_rank_on_a_six_joint_arm_and_sign_resolution():
    dh = [[0, 0, 0, 0.3], [-np.pi / 2, 0, 0, 0], [0, 0.4, 0, 0], [-np.pi / 2, 0.02, 0, 0.4],
          [np.pi / 2, 0, 0, 0], [-np.pi / 2, 0, 0, 0.08]]
    chain = DHChain.from_table(dh, joint_types="RRRRRR")
    rig = type(RIG)(chain=chain)
    q0 = np.array([0.1, -0.6, 0.5, 0.1, 0.5, 0.2])
    d, tr = simulate_fpdp(rig, np.random.default_rng(2), q0=q0, spread=np.full(6, 0.25), noise=False,
                          sphere_offset=(0, 0.012, 0.25))
    r = fpdp_calibrate(d.q, d.profiles, chain, d.sphere_radius)
    assert r.undetermined == ()
    assert max(transform_error(r.X, rig.X)) < 1e-9
    true_c = apply_transform(invert_transform(rig.T_W_L(d.q)), tr.sphere_centre)
    assert np.all(r.signs == np.sign(true_c[:, 1]))
    # the known-side option with the wrong side gives a worse fit, not silence
    r_wrong = fpdp_calibrate(d.q, d.profiles, chain, d.sphere_radius, sign=-1)
    assert r_wrong.rms > 100 * max(r.rms, 1e-9)


def test_fpdp_bad_input():
    d, _ = simulate_fpdp(RIG, np.random.default_rng(0), n_poses=6)
    with pytest.raises(InputError, match="counts must match"):
        fpdp_calibrate(d.q[:5], d.profiles, RIG.chain, d.sphere_radius)
    few = [p[:4] for p in d.profiles]
    with pytest.raises(NotEnoughDataError, match="at least 5 profiles"):
        fpdp_calibrate(d.q, few, RIG.chain, d.sphere_radius)
    q = d.q.copy()
    q[2, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        fpdp_calibrate(q, d.profiles, RIG.chain, d.sphere_radius)
