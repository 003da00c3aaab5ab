"""The core slip check: silent when plausible, names the explaining slip, refuses or warns."""

import math

import pytest

from robocal.errors import ImplausibleInputError, InputError
from robocal.plausibility import IMPLAUSIBLE_CODE, Slip, check_slips, try_slips
from robocal.resources import format_bytes, require_memory
from robocal.errors import ResourceError


def _never():
    raise AssertionError("a slip must not be tried when the answer is plausible")


def test_plausible_answer_tries_nothing():
    assert check_slips(what="residual", residual=0.4, unit="px", plausible=True, reason="-",
                       slips=[Slip("x", "x", "with x", _never)]) is None


def test_the_explaining_slip_is_named_in_one_line():
    slips = [Slip("deg_as_rad", "`angles` look like rad, not deg", "with deg->rad", lambda: 30.0),
             Slip("height_mm_as_m", "`height` looks like mm, not m", "with /1000", lambda: 0.4)]
    with pytest.raises(ImplausibleInputError) as info:
        check_slips(what="residual", residual=38.0, unit="px", plausible=False, reason="too large",
                    slips=slips, source="run.yaml: height")
    err = info.value
    assert err.slip == "height_mm_as_m"
    assert isinstance(err, InputError)
    text = str(err)
    assert "\n" not in text
    assert text.startswith("run.yaml: height: `height` looks like mm, not m: with /1000 the residual drops from 38 to 0.4 px")
    assert "--accept-implausible" in text


def test_a_slip_that_fails_or_helps_too_little_is_not_named():
    def boom():
        raise InputError("cannot refit")

    slips = [Slip("a", "a", "with a", boom), Slip("b", "b", "with b", lambda: math.nan),
             Slip("c", "c", "with c", lambda: 20.0)]  # 38 -> 20 is < 5x better
    with pytest.raises(ImplausibleInputError) as info:
        check_slips(what="residual", residual=38.0, unit="px", plausible=False,
                    reason="residual 38 px against 0.3 px noise", slips=slips)
    assert info.value.slip is None
    assert "none of the likely slips (a, b, c) explains it" in str(info.value)
    trial = try_slips(slips, 38.0)
    assert trial.tried == (("a", None), ("b", None), ("c", 20.0))


def test_threshold_must_also_be_met():
    trial = try_slips([Slip("a", "a", "with a", lambda: 1.0)], 100.0, threshold=0.5)
    assert trial.best is None


def test_accept_turns_the_error_into_a_named_warning():
    diag = check_slips(what="residual", residual=38.0, unit="px", plausible=False, reason="r",
                       slips=[Slip("s", "`s` is off", "with /1000", lambda: 0.1)], accept=True)
    assert diag.code == IMPLAUSIBLE_CODE and diag.params == ("s",)
    assert "accepted with --accept-implausible" in diag.message


def test_with_source_keeps_the_slip():
    err = ImplausibleInputError("m", slip="s").with_source("f.yaml")
    assert err.slip == "s" and str(err) == "f.yaml: m"


def test_require_memory_refuses_before_work_in_one_line():
    require_memory(1024, "tiny")  # fine anywhere
    with pytest.raises(ResourceError) as info:
        require_memory(2.0**60, "pairwise distances of 10^9 points", source="room.yaml")
    assert "needs 1024.0 PiB" not in str(info.value)  # sizes are capped at TiB
    assert str(info.value).startswith("room.yaml: pairwise distances of 10^9 points needs")
    assert isinstance(info.value, MemoryError)
    assert format_bytes(1536) == "1.5 KiB"


def test_a_finished_trial_is_judged_without_evaluating_again():
    calls = []

    def once():
        calls.append(1)
        return 0.4

    trial = try_slips([Slip("s", "`s` is off", "with /1000", once)], 38.0, unit="px")
    assert calls == [1]
    with pytest.raises(ImplausibleInputError, match="with /1000 the residual drops from 38 to 0.4 px") as info:
        check_slips(what="residual", residual=38.0, unit="px", plausible=False, reason="r", trial=trial)
    assert calls == [1] and info.value.slip == "s"
