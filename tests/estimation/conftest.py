"""Problem fixtures shared by the estimation tests (plain factories, seeded)."""

import numpy as np
import pytest

from robocal.estimation import Problem


def make_linear(seed=0, n_obs=40, sigma=0.05):
    """y = b0 + b1 t + b2 t^2 + noise; returns (problem, X, y, truth)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(-1.0, 2.0, n_obs)
    X = np.column_stack([np.ones_like(t), t, t**2])
    truth = np.array([0.5, -1.0, 0.3])
    y = X @ truth + rng.normal(0.0, sigma, n_obs)
    p = Problem(lambda q: X @ q["beta"] - y, jacobian=lambda q: {"beta": X})
    p.add_block("beta", np.zeros(3), labels=["b0", "b1", "b2"], unit="m")
    return p, X, y, truth


def make_exponential(seed=1, n_obs=60, sigma=0.02, truth=(2.0, 1.3, 0.5)):
    """y = a exp(-b t) + c with scalar blocks a, b, c; returns (problem, truth)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 4.0, n_obs)
    a, b, c = truth
    y = a * np.exp(-b * t) + c + rng.normal(0.0, sigma, n_obs)

    def res(q):
        return q["a"] * np.exp(-q["b"] * t) + q["c"] - y

    def jac(q):
        e = np.exp(-q["b"] * t)
        return {"a": e[:, None], "b": (-q["a"] * t * e)[:, None], "c": np.ones((n_obs, 1))}

    p = Problem(res, jacobian=jac)
    p.add_block("a", 1.0).add_block("b", 0.5).add_block("c", 0.0)
    return p, np.array(truth)


def make_circle(seed=2, n_obs=30, sigma=0.01):
    """Geometric circle fit: residual = |p - centre| - radius."""
    rng = np.random.default_rng(seed)
    ang = rng.uniform(0, 2 * np.pi, n_obs)
    centre, radius = np.array([1.0, -2.0]), 0.7
    pts = centre + radius * np.column_stack([np.cos(ang), np.sin(ang)]) + rng.normal(0, sigma, (n_obs, 2))

    def res(q):
        return np.linalg.norm(pts - q["centre"], axis=1) - q["radius"]

    def jac(q):
        d = pts - q["centre"]
        u = d / np.linalg.norm(d, axis=1, keepdims=True)
        return {"centre": -u, "radius": -np.ones((n_obs, 1))}

    p = Problem(res, jacobian=jac)
    p.add_block("centre", [0.8, -1.7], unit="m").add_block("radius", 0.5, unit="m")
    return p, np.array([1.0, -2.0, 0.7])


@pytest.fixture
def linear():
    return make_linear()


@pytest.fixture
def exponential():
    return make_exponential()


@pytest.fixture
def circle():
    return make_circle()


@pytest.fixture
def factories():
    """The factories themselves, for tests that need other seeds or sizes."""
    from types import SimpleNamespace

    return SimpleNamespace(linear=make_linear, exponential=make_exponential, circle=make_circle)
