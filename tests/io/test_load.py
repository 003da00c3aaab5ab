import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from robocal.errors import FileFormatError, NonFiniteError, RobocalError, ShapeError, UnitError
from robocal.io import load_csv, load_document, parse_document, to_si


def test_units_convert_to_si_inline_and_document_default():
    doc = parse_document(
        "units: {length: mm, angle: deg}\n"
        "pts: [[0, 0], [1000, 0]]\n"
        "h: {value: 2.9, unit: m}\n"
        "yaw: 90\n",
        source="room.yaml",
    )
    np.testing.assert_allclose(doc.array("pts", kind="length", shape=("N", 2)), [[0, 0], [1, 0]])
    assert doc.float("h", kind="length") == 2.9
    assert doc.float("yaw", kind="angle") == pytest.approx(np.pi / 2)


def test_errors_name_file_and_field():
    doc = parse_document("units: {length: mm}\npts: [[0, 0, 1]]\nbad: [1, .nan]\n", source="room.yaml")
    with pytest.raises(ShapeError, match=r"room.yaml: field 'pts': must have shape \(N, 2\), got \(1, 3\)"):
        doc.array("pts", kind="length", shape=("N", 2))
    with pytest.raises(FileFormatError, match=r"room.yaml: field 'missing': is missing"):
        doc.raw("missing")
    with pytest.raises(NonFiniteError, match=r"field 'bad'.*NaN"):
        doc.array("bad")
    with pytest.raises(UnitError, match=r"field 'pts': has no unit"):  # the file gives mm for lengths only
        doc.array("pts", kind="angle")


def test_missing_unit_is_an_error_not_a_guess():
    doc = parse_document("h: 2.9\n", source="x.yaml")
    with pytest.raises(UnitError, match="has no unit"):
        doc.float("h", kind="length")


def test_wrong_unit_kind_inline():
    doc = parse_document("h: {value: 3, unit: deg}\n", source="x.yaml")
    with pytest.raises(UnitError, match="needs a unit of length"):
        doc.float("h", kind="length")


def test_nested_documents_inherit_units_and_prefix():
    doc = parse_document("units: {length: cm}\nrig:\n  H: 290\n  items: [{x: 1}, {x: 2}]\n", source="a.yaml")
    sub = doc.sub("rig")
    assert sub.float("H", kind="length") == pytest.approx(2.9)
    items = sub.items_list("items")
    assert items[1].float("x", kind="length") == pytest.approx(0.02)
    with pytest.raises(FileFormatError, match=r"field 'rig.items\[0\].y'"):
        items[0].raw("y")


def test_load_document_files(tmp_path):
    p = tmp_path / "a.json"
    p.write_text(json.dumps({"units": {"length": "m"}, "x": 1.5}))
    assert load_document(p).float("x", kind="length") == 1.5
    bad = tmp_path / "b.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(FileFormatError, match=r"b.yaml: invalid YAML at line"):
        load_document(bad)
    with pytest.raises(FileFormatError, match="file not found"):
        load_document(tmp_path / "nope.yaml")
    with pytest.raises(FileFormatError, match="expected a .yaml"):
        load_document(tmp_path / "x.txt")
    empty = tmp_path / "e.yaml"
    empty.write_text("")
    with pytest.raises(FileFormatError, match="empty"):
        load_document(empty)


def test_yaml_is_safe_loaded(tmp_path):
    p = tmp_path / "evil.yaml"
    p.write_text("x: !!python/object/apply:os.system ['echo hacked']\n")
    with pytest.raises(FileFormatError):
        load_document(p)


def test_csv_units_and_errors(tmp_path):
    p = tmp_path / "prof.csv"
    p.write_text("# comment\nprofile, x [mm], z [mm]\n0, 1.0, 200\n0, 2.0, 201\n")
    t = load_csv(p, required=["profile", "x"])
    np.testing.assert_allclose(t.column("x", kind="length"), [0.001, 0.002])
    np.testing.assert_allclose(t.column("profile"), [0, 0])
    with pytest.raises(UnitError, match="needs a unit"):
        t.column("profile", kind="length")
    with pytest.raises(FileFormatError, match="column 'y' is missing"):
        t.column("y")
    p.write_text("x [mm], z [mm]\n1, nan\n")
    with pytest.raises(FileFormatError, match=r"row 1, column 'z': value is nan"):
        load_csv(p)
    p.write_text("x [mm], z [mm]\n1\n")
    with pytest.raises(FileFormatError, match="row 1 has 1 values, header has 2"):
        load_csv(p)
    p.write_text("x [furlong]\n1\n")
    with pytest.raises(UnitError, match="unknown unit 'furlong'"):
        load_csv(p)
    with pytest.raises(FileFormatError, match="missing column"):
        load_csv(tmp_path / "prof.csv", required=["q"], text="x [mm]\n1\n")


def test_to_si_rejects_unknown_unit():
    with pytest.raises(UnitError, match="unknown unit"):
        to_si(1.0, "inch")


@settings(max_examples=60, deadline=None)
@given(st.text(max_size=60))
def test_fuzz_any_text_gives_a_document_or_a_robocal_error(text):
    # Whatever a user puts in a file, the loader answers with a Document or a RobocalError.
    try:
        doc = parse_document(text, source="fuzz.yaml")
    except RobocalError:
        return
    try:
        doc.array("points", kind="length", shape=("N", 3))
    except RobocalError:
        pass
