"""Issue 16: the FK/IK fast paths (float64 arrays, checks as reductions) give the seed equations' numbers
and keep every check the per-element path had."""

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from robocal.errors import InputError, NonFiniteError, SingularConfigurationError
from robocal.geometry import wrap_angle
from robocal.rigs.projector.model import NearSingularityWarning, ProjectorModel, UnreachablePointError


def reference_spot(m, th):
    """The previous implementation: seed eq. (6) as h s1 s2 / c2, h c1 s2 / c2."""
    a1, a2 = th[..., 0] + m.offsets[0], th[..., 1] + m.offsets[1]
    rho = m.h * np.sin(a2) / np.cos(a2)
    return np.stack([rho * np.sin(a1), rho * np.cos(a1), np.full_like(rho, -m.H)], axis=-1)


def reference_ik(m, p):
    """The previous implementation: seed eq. (8), minus the offsets, pan through wrap_angle."""
    x, y = p[..., 0], p[..., 1]
    return np.stack([wrap_angle(np.arctan2(x, y) - m.offsets[0]), np.arctan2(np.hypot(x, y), m.h) - m.offsets[1]],
                    axis=-1)


@pytest.mark.parametrize("offsets", [(0.0, 0.0), (0.03, -0.02), (-0.04, 0.01)])
@pytest.mark.parametrize("shape", [(), (1,), (257,), (4, 33)])
def test_fast_paths_equal_the_seed_equations(offsets, shape):
    rng = np.random.default_rng(len(shape) + 7 * len(offsets))
    m = ProjectorModel(H=3.1, d1=0.15, d2=0.04, offsets=offsets, tilt_limit=math.radians(80))
    th = np.stack([rng.uniform(-math.pi, math.pi, shape), rng.uniform(0.01, m.tilt_limit - 0.05, shape)], axis=-1)
    f = m.spot(th)
    # |spot| <= h tan(80 deg) ~ 17 m; tan vs sin/cos and the argument's rounding amplified by 1/c2^2 <= 33:
    # ~1e-14 relative, so 1e-12 m
    assert f.shape == shape + (3,) and np.abs(f - reference_spot(m, th)).max() < 1e-12
    assert np.abs(m.spot_from_chain(th) - f).max() < 1e-12
    assert np.abs(m.spot_world(th) - m.to_world(reference_spot(m, th))).max() < 1e-12
    back = m.ik(f)
    d = back - reference_ik(m, f)
    d[..., 0] = wrap_angle(d[..., 0])  # pi and -pi are one pan
    assert back.shape == shape + (2,) and np.abs(d).max() < 1e-13  # a few ulps of pi
    assert np.all((back[..., 0] > -math.pi) & (back[..., 0] <= math.pi))
    assert np.abs(m.spot(back) - f).max() < 1e-10  # round trip (spot sensitivity to tilt <= h / c2^2 ~ 100 m/rad)
    assert np.abs(m.ik(f[..., :2]) - back).max() == 0.0  # 2 columns: the same numbers
    assert np.abs(m.spot_world(m.ik_world(m.spot_world(th))) - m.spot_world(th)).max() < 1e-10  # through R and t


def test_pan_at_minus_pi_is_wrapped_to_pi():
    m = ProjectorModel(H=3.0)
    p = np.array([[-0.0, -1.0, -3.0], [0.0, -1.0, -3.0]])  # atan2(-0.0, -1) = -pi
    assert m.ik(p)[:, 0].tolist() == [math.pi, math.pi]


def test_every_check_still_fires_on_float64_arrays():
    m = ProjectorModel(H=3.0, d1=0.1, offsets=(0.01, 0.0), tilt_limit=math.radians(70))
    th = np.array([[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]])
    for col in (0, 1):
        for bad in (np.nan, np.inf):
            t = th.copy()
            t[2, col] = bad
            for fn in (m.spot, m.spot_from_chain, m.beam_range, m.spot_jacobian, m.pose):
                with pytest.raises(NonFiniteError, match=r"theta contains NaN or infinity \(first at index \(2, "):
                    fn(t)
    t = th.copy()
    t[1, 1] = math.pi / 2
    for fn in (m.spot, m.spot_from_chain, m.beam_range, m.spot_jacobian):
        with pytest.raises(SingularConfigurationError, match=r"horizon .*index \(1,\)"):
            fn(t)
    t[1, 1] = math.radians(75)  # beyond the 70 deg limit, below the horizon
    for fn in (m.spot, m.spot_from_chain):
        with pytest.warns(NearSingularityWarning, match="beyond the tilt limit"):
            fn(t)
    p = m.spot(th)
    with pytest.raises(InputError, match="floor is z_0"):
        m.ik(p + [0.0, 0.0, 1e-5])
    q = p.copy()
    q[0, 0] = np.nan
    with pytest.raises(NonFiniteError, match="points"):
        m.ik(q)
    with pytest.raises(NonFiniteError, match="points_W"):
        m.ik_world(np.array([[np.nan, 0.0]]))
    q[0, 0] = np.inf
    with pytest.raises(NonFiniteError):
        m.ik(q, check_reach=False)
    with pytest.raises(UnreachablePointError, match=r"point\(s\) \[1\]"):
        m.ik(np.array([[0.1, 0.1], [50.0, 0.0]]))
    with pytest.warns(NearSingularityWarning, match="nadir"):
        out = m.ik(np.array([[0.0, 0.0, -3.0], [0.2, 0.3, -3.0]]))
    assert np.all(np.isfinite(out))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the common case warns of nothing
        m.spot(th), m.ik(p), m.spot_from_chain(th)


def test_per_model_constants_follow_the_model():
    # spot / ik keep their constants per (frozen) model: a copy with other offsets, height or limit must not
    # reuse the first model's; |o1| >= pi (the fast path's pan wrap does not apply) takes the checked path
    rng = np.random.default_rng(116)
    th = np.column_stack([rng.uniform(-math.pi, math.pi, 50), rng.uniform(0.05, 1.0, 50)])
    m = ProjectorModel(H=3.0, d1=0.1, offsets=(0.01, 0.02), tilt_limit=math.radians(70))
    m.spot(th), m.ik(m.spot(th))  # fill the first model's constants
    for other in (m.with_(offsets=(-0.3, 0.04)), m.with_(H=4.0), m.with_(offsets=(3.5, 0.0))):
        f = other.spot(th)
        assert np.abs(f - reference_spot(other, th)).max() < 1e-12  # as in the test above
        d = other.ik(f) - reference_ik(other, f)
        d[..., 0] = wrap_angle(d[..., 0])
        assert np.abs(d).max() < 1e-13
    with pytest.warns(NearSingularityWarning, match="beyond the tilt limit"):
        m.with_(tilt_limit=math.radians(50)).spot(th * [1.0, 0.0] + [0.0, math.radians(60)])


# ---------------------------------------------------------------- the fused checks against the elementwise ones
# spot / ik decide "every check passes" by a few argmin / argmax passes and otherwise run the per-element
# checks, which name the element. A list input always takes the per-element path (the fast paths want a
# float64 ndarray), so comparing an array call with the same values as a list compares the two decisions:
# the fast path must never accept what the elementwise checks would refuse or warn about, and where it
# accepts it must give the same numbers.

def _outcome(fn, *args, **kw):
    """('raised', type, message) or ('ok', result, [(warning category, message)]), every warning recorded."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            out = fn(*args, **kw)
        except Exception as e:  # noqa: BLE001 - the type and message are what is compared
            return ("raised", type(e), str(e))
    return ("ok", out, [(w.category, str(w.message)) for w in caught])


_MODELS = [ProjectorModel(H=2.78, d1=0.02, offsets=(0.004, 0.005), tilt_limit=math.radians(75)),
           ProjectorModel(H=3.0, offsets=(-0.03, -0.02), tilt_limit=math.radians(60)),
           ProjectorModel(H=4.0, d1=0.1, offsets=(0.0, 0.0), tilt_limit=math.radians(89.9))]


def _edges(m):
    """Values where a check flips: the tilt limit +- an ulp (with its 1e-12 margin and the offset), the
    horizon, the nadir, NaN, +-inf, huge finite values (a sum or a square of them would overflow)."""
    lim = m.tilt_limit + 1e-12
    o2 = m.offsets[1]
    vals = [math.nan, math.inf, -math.inf, 1e308, -1.7e308, 1e154, 0.0, -0.0, math.pi / 2 - o2, -math.pi / 2 - o2,
            math.pi, -math.pi, 3 * math.pi / 2]
    for b in (lim - o2, -lim - o2):
        vals += [b, math.nextafter(b, math.inf), math.nextafter(b, -math.inf)]
    return vals


@st.composite
def _theta_case(draw):
    m = draw(st.sampled_from(_MODELS))
    shape = draw(st.sampled_from([(1, 2), (5, 2), (17, 2), (2,), (3, 4, 2)]))
    size = math.prod(shape)
    # mostly ordinary angles (the fast path's case), sometimes an edge value in either column
    ordinary = st.floats(-1.2, 1.2, allow_nan=False)
    vals = draw(st.lists(st.one_of(ordinary, ordinary, ordinary, st.sampled_from(_edges(m))),
                         min_size=size, max_size=size))
    return m, np.array(vals, dtype=float).reshape(shape)


@settings(max_examples=200, deadline=None)
@given(_theta_case())
def test_spot_fused_checks_decide_as_the_elementwise_checks(case):
    m, th = case
    fast, ref = _outcome(m.spot, th), _outcome(m.spot, th.tolist())
    assert fast[0] == ref[0]
    if fast[0] == "raised":
        assert fast[1:] == ref[1:]  # same error, same message (naming the element)
    else:
        assert fast[2] == ref[2]  # same warnings (none of NumPy's RuntimeWarnings either)
        assert np.array_equal(fast[1], ref[1])  # the same IEEE operations on both paths: equal, not close


@st.composite
def _points_case(draw):
    """Floor points within reach (pans with the wrap's edges +-pi among them), then up to two corrupted:
    at or beyond the reach radius, at the nadir, infinite, NaN, or off the floor by about floor_tol."""
    m = draw(st.sampled_from(_MODELS))
    n = draw(st.integers(1, 12))
    r_reach = m.h * math.tan(m.tilt_limit)
    r = np.array(draw(st.lists(st.floats(1e-6, 0.999 * r_reach), min_size=n, max_size=n)))
    phi = np.array(draw(st.lists(st.sampled_from([math.pi, -math.pi, -math.pi / 2, 0.0]) | st.floats(-4, 4),
                                 min_size=n, max_size=n)))
    p = np.column_stack([r * np.sin(phi), r * np.cos(phi), np.full(n, -m.H)])
    for _ in range(draw(st.integers(0, 2))):
        i = draw(st.integers(0, n - 1))
        col, v = draw(st.sampled_from([
            (0, 0.0), (1, 0.0), (1, 1e-12), (0, math.nan), (1, math.inf), (0, -math.inf), (1, r_reach),
            (1, math.nextafter(r_reach, 0.0)), (1, math.nextafter(r_reach, math.inf)), (1, r_reach * (1 + 1e-9)),
            (0, 1.5 * r_reach),
            (2, -m.H + 1e-6), (2, -m.H - 1e-6), (2, -m.H + 1.2e-6), (2, -m.H - 1.2e-6), (2, math.nan)]))
        if col < 2:
            p[i, 1 - col] = 0.0  # the value is the point's distance from the nadir
        p[i, col] = v
    return m, p[:, :draw(st.sampled_from([2, 3]))]


@settings(max_examples=120, deadline=None)
@given(_points_case())
def test_ik_fused_checks_decide_as_the_elementwise_checks(case):
    m, p = case
    for kw in ({}, {"check_reach": False}, {"on_nadir": "raise"}):
        fast, ref = _outcome(m.ik, p, **kw), _outcome(m.ik, p.tolist(), **kw)
        assert fast[0] == ref[0]
        if fast[0] == "raised":
            assert fast[1:] == ref[1:]
        else:
            assert fast[2] == ref[2]
            d = fast[1] - ref[1]
            d[..., 0] = wrap_angle(d[..., 0])  # pi and -pi are one pan
            # atan(r / h) vs atan2(r, h) and the pan's one shift vs wrap_angle: a few ulps of pi
            assert np.abs(d).max() < 1e-13
            assert np.all((fast[1][..., 0] > -math.pi) & (fast[1][..., 0] <= math.pi))
