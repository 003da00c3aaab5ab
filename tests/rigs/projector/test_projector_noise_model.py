"""Issue 19: the encoder noise in the model, checked on data from an independent generator.

:func:`independent_room` is written from seed 000's equations alone (eq. 1
``^0P = R ^WP + t``, eq. 6 the spot ``f(theta)``), not from the rig's
``simulate``: random rooms (H 2.5-4.5 m, yaw +-180 deg), N floor points at
actual tilts 10-60 deg, world noise 5 mm, encoder noise 0.05 deg.
``bench/bench_projector_noise.py`` runs the full study with it (figures in BENCHMARKS.md).
"""

from __future__ import annotations

import math

import numpy as np

WORLD_SIGMA = 0.005  # m
JOINT_SIGMA = math.radians(0.05)  # rad, pan and tilt
ROOMS = 150  # Monte Carlo trials of the suite's test (~10 s)


def independent_room(rng: np.random.Generator, n: int, *, world_sigma: float = WORLD_SIGMA,
                     joint_sigma: float = JOINT_SIGMA, tilts=(10.0, 60.0)) -> dict:
    """One random room and its calibration data, from seed 000 eqs. (1) and (6) only.

    Returns a dict: ``H``, ``h_true``, ``d1_nominal``, ``tilt_offset`` (rad), ``yaw`` (rad), ``t`` (3,),
    ``world`` (n, 2) measured floor points (m), ``theta`` (n, 2) recorded joint angles (rad),
    ``world_true`` (n, 2).
    """
    H = rng.uniform(2.5, 4.5)
    d1 = rng.uniform(0.05, 0.25)
    h = H - d1
    o2 = math.radians(rng.normal(0.0, 0.5))  # tilt zero offset; the pan offset is not identifiable: 0
    yaw = rng.uniform(-math.pi, math.pi)
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # R_0_W = Rz(yaw)
    nadir_W = np.array([*rng.uniform(-3.0, 3.0, 2), 0.0])
    t = np.array([0.0, 0.0, -H]) - R @ nadir_W  # the nadir (0, 0, -H) in {0} is nadir_W in {W} (eq. 1)
    a1 = rng.uniform(-math.pi, math.pi, n)  # actual pan, tilt of the head at each spot
    a2 = np.radians(rng.uniform(*tilts, n))
    f = np.column_stack([h * np.sin(a1) * np.tan(a2), h * np.cos(a1) * np.tan(a2), np.full(n, -H)])  # eq. 6
    world_true = (f - t) @ R  # eq. 1 inverted: R^T (f - t)
    theta = np.column_stack([a1, a2 - o2]) + rng.normal(0.0, joint_sigma, (n, 2))  # commanded = actual - offset
    world = world_true[:, :2] + rng.normal(0.0, world_sigma, (n, 2))
    return dict(H=H, h_true=h, d1_nominal=d1 + rng.normal(0.0, 0.01), tilt_offset=o2, yaw=yaw, t=t,
                world=world, theta=theta, world_true=world_true[:, :2])


def calibrate_room(room: dict, *, joint_noise: bool = True, joint_sigma: float = JOINT_SIGMA):
    """The rig's calibration of one room (nonlinear, h and tilt offset estimated, noise stated)."""
    from robocal.rigs.projector.calibrate import calibrate
    from robocal.rigs.projector.model import ProjectorModel

    nominal = ProjectorModel(H=room["H"], d1=room["d1_nominal"])
    return calibrate(room["world"], theta=room["theta"], model=nominal, methods=("closed_form", "nonlinear"),
                     estimate=("h", "tilt_offset"), sigma=WORLD_SIGMA,
                     joint_noise=(joint_sigma, joint_sigma) if joint_noise else None)


def z_scores(room: dict, run) -> dict:
    """(estimate - truth) / reported std of each estimated parameter."""
    b = run.best
    err = {"yaw": math.remainder(b.yaw - room["yaw"], 2 * math.pi), "t_x": b.t_0_W[0] - room["t"][0],
           "t_y": b.t_0_W[1] - room["t"][1], "h": b.extra["h"] - room["h_true"],
           "tilt_offset": b.extra["offsets"][1] - room["tilt_offset"]}
    return {k: v / b.std[k] for k, v in err.items()}


def flagged(run) -> tuple[bool, bool]:
    """(inconsistent_data raised, outliers raised) for a run."""
    codes = {w.code for w in run.warnings}
    return "inconsistent_data" in codes, "outliers" in codes


def test_independent_generator_obeys_seed_eq_6_through_the_rig_model():
    """The generator and the rig's model agree on the spot (both from eq. 6): a check of the generator,
    not of the rig. Exact data (no noise): the rig's spot of the recorded angles, moved by the true
    extrinsics, is the true world point to rounding (1e-12 m at room scale)."""
    from robocal.rigs.projector.model import ProjectorModel

    room = independent_room(np.random.default_rng(1), 10, world_sigma=0.0, joint_sigma=0.0)
    c, s = math.cos(room["yaw"]), math.sin(room["yaw"])
    m = ProjectorModel(H=room["H"], d1=room["H"] - room["h_true"], offsets=(0.0, room["tilt_offset"]),
                       R_0_W=np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), t_0_W=room["t"])
    assert np.allclose(m.to_world(m.spot(room["theta"]))[:, :2], room["world_true"], atol=1e-12)


def test_encoder_noise_monte_carlo_std_ratio_and_false_alarms():
    """Issue 19's Monte Carlo, small enough for the suite (fixed seed).

    ROOMS rooms at N = 20 with encoder noise 0.05 deg stated as joint_noise. The
    RMS of z = error / std over 150 rooms has a relative standard error of about
    1 / sqrt(2 * 150) = 5.8 % per parameter; the band 0.85-1.2 is -2.6 / +3.4 of
    it around 1 (a correct model passes with ~99 % probability per parameter),
    and a model that ignores the joint noise (ratio 1.25-1.35 in the issue) fails.
    False alarms (inconsistent_data or outliers): <= 5 % allowed, i.e. 7 of 150;
    each test is designed for <= 1 %, measured 0-3 % (bench/bench_projector_noise.py),
    and 8 or more alarms at a true 2 % rate has probability 3 %.
    """
    rng = np.random.default_rng(20260127)
    z, alarms = [], 0
    for _ in range(ROOMS):
        room = independent_room(rng, 20)
        run = calibrate_room(room)
        assert "held" not in run.best.extra
        z.append(list(z_scores(room, run).values()))
        alarms += any(flagged(run))
    ratio = np.sqrt(np.mean(np.square(z), axis=0))
    assert np.all((ratio > 0.85) & (ratio < 1.2)), dict(zip(["yaw", "t_x", "t_y", "h", "tilt_offset"], ratio))
    assert alarms <= 0.05 * ROOMS, alarms


def test_the_joint_noise_term_is_what_makes_the_std_right():
    """Encoder noise 0.15 deg (3x the issue's): stated, the std ratio stays near 1; left out of the input, the
    std is far too small (ratio > 1.5 for the worst parameter). 30 rooms: relative SE of a ratio ~13 %."""
    sig = math.radians(0.15)
    rng = np.random.default_rng(7)
    z_with, z_without = [], []
    for _ in range(30):
        room = independent_room(rng, 20, joint_sigma=sig)
        z_with.append(list(z_scores(room, calibrate_room(room, joint_sigma=sig)).values()))
        z_without.append(list(z_scores(room, calibrate_room(room, joint_noise=False)).values()))
    with_, without = (np.sqrt(np.mean(np.square(z), axis=0)) for z in (z_with, z_without))
    assert np.all((with_ > 0.75) & (with_ < 1.3)), with_
    assert without.max() > 1.5, without


def test_a_planted_outlier_is_named_first():
    """30 cm on one of 8 points: flagged and named first (by the outlier test and the pairwise check)."""
    rng = np.random.default_rng(5)
    first = 0
    for _ in range(20):
        room = independent_room(rng, 8)
        k = int(rng.integers(8))
        ang = rng.uniform(0, 2 * math.pi)
        room["world"][k] += 0.30 * np.array([math.cos(ang), math.sin(ang)])
        run = calibrate_room(room)
        out = [w for w in run.warnings if w.code == "outliers"]
        assert out, "the 30 cm point was not flagged"
        first += out[0].indices[0] == k
    assert first >= 18, first  # the goal is >= 90 %
