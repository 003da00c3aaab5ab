"""Bad input: missing images, images without a board, joints out of limits, mismatched counts."""

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from robocal.errors import (FileFormatError, ImplausibleInputError, InconsistentDataError, InputError,
                            NotEnoughDataError)
from robocal.rigs.humanoid.calibrate import calibrate
from robocal.rigs.humanoid.dataset import load_dataset

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "humanoid"


@pytest.fixture
def example(tmp_path):
    shutil.copytree(EXAMPLE, tmp_path / "ex")
    return tmp_path / "ex" / "run.yaml"


def _edit(path, fn):
    d = yaml.safe_load(path.read_text())
    fn(d)
    path.write_text(yaml.safe_dump(d, sort_keys=False))


def test_example_loads_and_detects(example):
    model, data, info = load_dataset(example)
    assert data.n_views == 8 and np.all(np.isfinite(data.corners))
    assert info["joint_resolution"] == pytest.approx(np.radians(0.1))
    assert len(info["inputs"]) == 9


def test_missing_image_file(example):
    (example.parent / "images" / "view003.png").unlink()
    with pytest.raises(FileFormatError, match="view003.png"):
        load_dataset(example)


def test_image_without_a_board_is_dropped_with_a_message(example):
    cv2.imwrite(str(example.parent / "images" / "view002.png"), np.full((480, 640), 128, np.uint8))
    model, data, _ = load_dataset(example)
    assert np.all(np.isnan(data.corners[2])) and np.all(np.isfinite(data.corners[[0, 1, 3]]))
    assert any("view002" in m and "dropped" in m for m in data.messages)
    cal = calibrate(model, data)
    assert cal.data.n_views == 7 and "view002" not in cal.data.names
    assert any(w.code == "dropped" for w in cal.warnings)


def test_no_board_in_any_image(example):
    for p in (example.parent / "images").glob("*.png"):
        cv2.imwrite(str(p), np.full((480, 640), 200, np.uint8))
    model, data, _ = load_dataset(example)
    with pytest.raises(NotEnoughDataError, match="no view with a fully detected board"):
        calibrate(model, data)


def test_image_of_the_wrong_size(example):
    cv2.imwrite(str(example.parent / "images" / "view001.png"), np.zeros((240, 320), np.uint8))
    with pytest.raises(InputError, match="view001.*320 x 240"):
        load_dataset(example)


def test_unreadable_image(example):
    (example.parent / "images" / "view001.png").write_bytes(b"not a png")
    with pytest.raises(FileFormatError, match=r"view001\.png.*not an image OpenCV can decode"):
        load_dataset(example)


def test_joint_angle_out_of_limits(example):
    def fn(d):
        k = d["joints"]["names"].index("LKneePitch")
        d["joints"]["records"][1][k] = 135.0
    _edit(example, fn)
    with pytest.raises(InputError, match=r"records\[1\]: joint 'LKneePitch' = 135.00 deg is outside its limits"):
        load_dataset(example)


@pytest.mark.parametrize("field", ["images", "feet", "records"])
def test_mismatched_counts(example, field):
    def fn(d):
        if field == "records":
            d["joints"]["records"].pop()
        else:
            d[field].pop()
    _edit(example, fn)
    with pytest.raises(InconsistentDataError, match="one foot and one joint record per image"):
        load_dataset(example)


def test_malformed_joint_records(example):
    _edit(example, lambda d: d["joints"]["names"].remove("RAnkleRoll"))
    with pytest.raises(FileFormatError, match="each row must hold"):
        load_dataset(example)
    _edit(example, lambda d: [row.pop() for row in d["joints"]["records"]])
    with pytest.raises(InputError, match="missing joint angles for \\['RAnkleRoll'\\]"):
        load_dataset(example)
    # a quoted angle, or a row one angle short, through the shared loader's messages
    _edit(example, lambda d: d["joints"]["records"][0].__setitem__(1, "25.8"))
    with pytest.raises(FileFormatError, match=r"joints.records'?: contains a quoted string \('25.8'\) at index \(0, 1\)"):
        load_dataset(example)
    _edit(example, lambda d: d["joints"]["records"][0].__setitem__(1, 25.8) or d["joints"]["records"][2].pop())
    with pytest.raises(InputError, match=r"rows of different lengths: row 0 has \d+ entries, row 2 has"):
        load_dataset(example)


def test_bad_fields(example):
    _edit(example, lambda d: d["feet"].__setitem__(0, "middle"))
    with pytest.raises(FileFormatError, match="feet"):
        load_dataset(example)
    _edit(example, lambda d: (d["feet"].__setitem__(0, "left"), d["joints"].__setitem__("unit", "grad")))
    with pytest.raises(FileFormatError, match="unit"):
        load_dataset(example)
    _edit(example, lambda d: (d["joints"].__setitem__("unit", "deg"), d.__setitem__("format", "other/1")))
    with pytest.raises(FileFormatError, match="format"):
        load_dataset(example)


def test_mislabelled_foot_is_refused(example):
    # before: exit 0 with LHipRoll +50 deg, LKneePitch -61 deg and a corrected URDF written
    _edit(example, lambda d: d["feet"].__setitem__(4, "left" if d["feet"][4] == "right" else "right"))
    model, data, _ = load_dataset(example)
    with pytest.raises(InconsistentDataError, match="view 'view004'.*foot label does not match the image"):
        calibrate(model, data)


def test_consistency_thresholds_are_parameters(example, model, corner_data, capsys):
    from robocal.cli.main import main
    from robocal.rigs.humanoid.calibrate import NOMINAL_MIN_PX, NOMINAL_RATIO, check_views_consistent
    from robocal.rigs.humanoid.cli import RIG

    dist = check_views_consistent(model, corner_data)  # defaults: 60 px, 4 x the median view
    assert dist.max() < NOMINAL_MIN_PX == 60.0 and NOMINAL_RATIO == 4.0
    # tighter than the spread of good views: the farthest one is refused
    with pytest.raises(InconsistentDataError, match=f"view {corner_data.names[int(np.argmax(dist))]!r}"):
        calibrate(model, corner_data, consistency_px=1.0, consistency_ratio=1.0)
    check_views_consistent(model, corner_data, min_px=dist.max() + 1, ratio=1.0)
    for kw in ({"consistency_px": 0.0}, {"consistency_px": np.nan}, {"consistency_ratio": 0.5}):
        with pytest.raises(InputError, match="consistency"):
            calibrate(model, corner_data, **kw)
    # the CLI passes its flags through (the example passes the defaults: test_calibrate_example_and_report)
    out = str(example.parent / "out")
    assert main(["humanoid", "calibrate", str(example), "--consistency-px", "1", "--consistency-ratio", "1",
                 "--out", out]) == 2
    assert "expected < " in capsys.readouterr().err
    # the mislabelled foot (250+ px) passes a threshold set beyond it; the offsets it pulls to (tens of
    # deg) are then implausible: an error, or with accept_implausible a warning
    _edit(example, lambda d: d["feet"].__setitem__(4, "left" if d["feet"][4] == "right" else "right"))
    m, data, _ = load_dataset(example)
    with pytest.raises(ImplausibleInputError, match=r"implausible offsets \(> 5 deg\)"):
        calibrate(m, data, consistency_px=1000.0)
    cal = calibrate(m, data, consistency_px=1000.0, accept_implausible=True)
    assert any(w.code == "implausible_input" and "implausible offsets" in w.message for w in cal.warnings)
    # the CLI's defaults are the library's
    import argparse

    from robocal.cli._workflow import add_workflow_commands

    parser = argparse.ArgumentParser()
    add_workflow_commands(parser, RIG)
    args = parser.parse_args(["calibrate", "x.yaml"])
    assert (args.consistency_px, args.consistency_ratio) == (NOMINAL_MIN_PX, NOMINAL_RATIO)


def test_swapped_joint_records_are_refused(example):
    # before: exit 0 with LKneePitch -160.7 deg (outside its own limits)
    _edit(example, lambda d: d["joints"]["records"].__setitem__(slice(0, 2), d["joints"]["records"][1::-1]))
    model, data, _ = load_dataset(example)
    with pytest.raises(InconsistentDataError, match="view 'view00[01]'.*joint record"):
        calibrate(model, data)


def test_implausible_offsets_are_a_warning(model, corner_data):
    from robocal.rigs.humanoid.calibrate import plausibility_warnings

    labels = model.parameter_labels()
    x = np.zeros(len(labels))
    x[labels.index("LKneePitch")] = np.radians(-61.0)
    rms = np.full(8, 0.2)
    rms[3] = 25.0
    w = plausibility_warnings(model, model.seed_parameters(), x, rms, [f"v{i}" for i in range(8)], 1.0)
    assert [d.code for d in w] == ["inconsistent_data"] * 2
    assert "LKneePitch -61.0 deg" in w[0].message and "v3 25.0 px" in w[1].message
    assert plausibility_warnings(model, model.seed_parameters(), x * 0, rms * 0 + 0.2, list("abcdefgh"), 1.0) == []
