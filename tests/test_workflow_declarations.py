"""robocal.workflow: the declarations a rig writes (Option, Command, Workflow) and the argument types."""

import argparse

import pytest

from robocal.workflow import Command, Option, Workflow, number_at_least, resolve, seed_value


def test_option_dest_and_step():
    assert Option("--no-refine", action="store_true").dest == "no_refine"
    assert Option("-s", "--sigma", dest="sigma_px").dest == "sigma_px"
    assert Option("input").dest == "input"
    assert Option("--seed", to=None).to is None


def test_workflow_refuses_half_a_calibrate_and_twice_declared_commands():
    with pytest.raises(ValueError, match="come together"):
        Workflow("x", "h", calibrate="m:f")
    with pytest.raises(ValueError, match="declared twice"):
        Workflow("x", "h", commands=(Command("plan", "h", run="m:f"), Command("plan", "h", run="m:g")))
    with pytest.raises(ValueError, match="declared twice"):
        Workflow("x", "h", simulate="m:f", commands=(Command("simulate", "h", run="m:f"),))


def test_steps_resolve_lazily_from_module_attr():
    wf = Workflow("x", "h", demo="math:sqrt")
    assert wf.step("demo")(4.0) == 2.0
    assert wf.step("simulate") is None
    assert resolve(len) is len
    with pytest.raises(ValueError, match="module:attribute"):
        resolve("math.sqrt")
    with pytest.raises(ValueError, match="unknown step"):
        wf.step("fly")


@pytest.mark.parametrize("kind, minimum, strict, text, ok", [
    (int, 1, False, "1", True), (int, 1, False, "0", False), (int, 1, False, "1.5", False),
    (float, 0.0, False, "0", True), (float, 0.0, True, "0", False), (float, 0.0, False, "nan", False),
    (float, 0.0, False, "inf", False), (float, 0.0, False, "-1e-9", False),
])
def test_number_at_least(kind, minimum, strict, text, ok):
    parse = number_at_least(kind, minimum, strict=strict, why="reason", unit="mm")
    if ok:
        assert parse(text) == kind(text)
    else:
        with pytest.raises(argparse.ArgumentTypeError, match="expected|must be"):
            parse(text)


def test_number_at_least_message_says_why():
    with pytest.raises(argparse.ArgumentTypeError, match=r"must be >= 2 \(needs two\), got 1"):
        number_at_least(int, 2, why="needs two")("1")


def test_seed_value():
    assert seed_value("7") == 7
    for bad in ("-1", "x", "1.5"):
        with pytest.raises(argparse.ArgumentTypeError, match="whole number >= 0"):
            seed_value(bad)
