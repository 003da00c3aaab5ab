"""calibrate_hand_eye judges plausibility on its own closed form when that passes outright (issue 16): the
same verdicts as the full check (judge_poses), and no second closed form on clean data."""

from pathlib import Path

import numpy as np
import pytest

from robocal.errors import ImplausibleInputError
from robocal.geometry import invert_transform
from robocal.handeye import calibrate_hand_eye, judge_poses, simulate_eye_in_hand
from robocal.handeye import plausibility as P
from robocal.io import load_poses

EX = Path(__file__).resolve().parents[2] / "examples" / "lineprofiler"


def _verdict(fn):
    try:
        fn()
    except ImplausibleInputError as exc:
        return exc.slip
    return None


def _scaled(T, k):
    T = T.copy()
    T[:, :3, 3] *= k
    return T


def _swapped(T, a, b):
    T = T.copy()
    T[[a, b]] = T[[b, a]]
    return T


def _cases():
    g, c = load_poses(EX / "gripper_poses.csv").T, load_poses(EX / "target_poses.csv").T
    sims = [simulate_eye_in_hand(np.random.default_rng(s), n) for s, n in ((0, 15), (1, 8), (2, 30))]
    out = {"example": (g, c)}
    out |= {f"sim{k}": (s.T_base_gripper, s.T_cam_target) for k, s in enumerate(sims)}
    Tg, Tc = sims[0].T_base_gripper, sims[0].T_cam_target
    out |= {
        "example target m as mm": (g, _scaled(c, 1e-3)),      # 5.6 mm on all pairs: below TRANS_FLOOR
        "example gripper mm": (_scaled(g, 1e3), c),
        "target mm": (Tg, _scaled(Tc, 1e3)),
        "target inverted": (Tg, invert_transform(Tc)),
        "gripper inverted": (invert_transform(Tg), Tc),
        "poses 3 and 11 swapped": (Tg, _swapped(Tc, 3, 11)),
    }
    return out


CASES = _cases()


@pytest.mark.parametrize("name", sorted(CASES))
def test_same_verdict_as_the_full_check(name):
    Tg, Tc = CASES[name]
    full = _verdict(lambda: judge_poses(Tg, Tc))
    assert _verdict(lambda: calibrate_hand_eye(Tg, Tc, refine=False)) == full
    # the cases must include both outcomes, or the comparison says nothing
    assert (full is None) == (name == "example" or name.startswith("sim")), (name, full)


def test_clean_lists_need_no_second_closed_form(monkeypatch):
    calls = []
    real = P._closure_residuals
    monkeypatch.setattr(P, "_closure_residuals", lambda *a, **k: calls.append(1) or real(*a, **k))
    for name in ("example", "sim0", "sim1", "sim2"):
        calibrate_hand_eye(*CASES[name], refine=False)
    assert calls == []
    with pytest.raises(ImplausibleInputError):
        calibrate_hand_eye(*CASES["target mm"], refine=False)
    assert calls                                   # an implausible pair is judged in full
