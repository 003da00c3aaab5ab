import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import yaml

from robocal.errors import FileFormatError, InputError, NonFiniteError, RobocalError, ShapeError, UnitError
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
    with pytest.raises(FileFormatError, match=r"row 1 \(line 2\), column 'z': value is nan"):
        load_csv(p)
    p.write_text("x [mm], z [mm]\n1\n")
    with pytest.raises(FileFormatError, match=r"row 1 \(line 2\) has 1 values, header has 2"):
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


def test_csv_errors_name_the_file_line(tmp_path):
    # "row N" counts data rows; with comments and blank lines the file line differs, and both are given.
    p = tmp_path / "prof.csv"
    p.write_text("# scan 7\n\nx [mm], z [mm]\n1, 2\n\n# second pass\n3, nan\n4, 5\n")
    with pytest.raises(FileFormatError, match=r"prof.csv: row 2 \(line 7\), column 'z': value is nan"):
        load_csv(p)
    p.write_text("x [mm], z [mm]\n# skipped\n1, 2\n3, abc\n")
    with pytest.raises(FileFormatError, match=r"row 2 \(line 4\), column 'z': not a number: ' abc'"):
        load_csv(p)
    p.write_text("x [mm], z [mm]\n\n\n1, 2, 3\n")
    with pytest.raises(FileFormatError, match=r"row 1 \(line 4\) has 3 values, header has 2"):
        load_csv(p)
    t = load_csv(p, text="# c\nx [mm]\n1\n\n2\n")
    assert t.lines.tolist() == [3, 5]
    assert t.where(1) == "row 2 (line 5)"


def test_utf8_bom_is_not_part_of_the_first_name(tmp_path):
    # Excel's "CSV UTF-8" starts the file with a byte-order mark.
    p = tmp_path / "pts.csv"
    p.write_text("x [mm], y [mm]\n1, 2\n", encoding="utf-8-sig")
    assert p.read_bytes().startswith(b"\xef\xbb\xbf")
    t = load_csv(p, required=["x", "y"])
    np.testing.assert_allclose(t.column("x", kind="length"), [0.001])
    assert load_csv(p, text=p.read_text(encoding="utf-8")).units["x"] == "mm"
    for name, text in [("a.json", '{"units": {"length": "mm"}, "h": 2900}'), ("a.yaml", "units: {length: mm}\nh: 2900\n")]:
        f = tmp_path / name
        f.write_text(text, encoding="utf-8-sig")
        assert load_document(f).float("h", kind="length") == pytest.approx(2.9)


@pytest.mark.parametrize(
    "suffix, text, match",
    [
        (".yaml", "units: {length: m}\nH: true\n", r"x.yaml: field 'H': must be a number, got a boolean \(true\)"),
        (".yaml", "H: {value: false, unit: m}\n", r"x.yaml: field 'H': must be a number, got a boolean \(false\)"),
        (".yaml", "units: {length: m}\nH: [1.0, [2, true]]\n",
         r"x.yaml: field 'H': must contain numbers only, got a boolean \(true\) at index \(1, 1\)"),
        (".json", '{"units": {"length": "m"}, "H": [true, 2]}',
         r"x.json: field 'H': must contain numbers only, got a boolean \(true\) at index \(0,\)"),
    ],
)
def test_booleans_are_not_numbers(suffix, text, match):
    doc = parse_document(text, suffix=suffix, source=f"x{suffix}")
    with pytest.raises(InputError, match=match):
        doc.array("H", kind="length")
    with pytest.raises(InputError, match="boolean"):
        doc.array("H")


@pytest.mark.parametrize(
    "suffix, text, match",
    [
        (".yaml", 'units: {length: m}\nH: "2.9"\n', r"^x.yaml: field 'H': is a quoted string \('2.9'\), expected a number$"),
        (".yaml", "units: {length: m}\nH: '1e3'\n", r"^x.yaml: field 'H': is a quoted string \('1e3'\), expected a number$"),
        (".yaml", 'H: {value: "2.9", unit: m}\n', r"^x.yaml: field 'H': is a quoted string \('2.9'\), expected a number$"),
        (".yaml", 'units: {length: m}\nH: [[1, 2], [3, "4"]]\n',
         r"^x.yaml: field 'H': contains a quoted string \('4'\) at index \(1, 1\), expected a number$"),
        (".json", '{"units": {"length": "m"}, "H": "2.9"}', r"^x.json: field 'H': is a quoted string \('2.9'\), expected a number$"),
        (".json", '{"units": {"length": "m"}, "H": [1.0, "-0.5"]}',
         r"^x.json: field 'H': contains a quoted string \('-0.5'\) at index \(1,\), expected a number$"),
        (".yaml", "units: {length: m}\nH: tall\n", r"^x.yaml: field 'H': is a string \('tall'\), expected a number$"),
        (".yaml", "units: {length: m}\nH: [1, nan]\n",
         r"^x.yaml: field 'H': contains a string \('nan'; YAML spells these \.nan, \.inf, -\.inf\) at index \(1,\), expected a number$"),
    ],
)
def test_quoted_numbers_are_not_numbers(suffix, text, match):
    """A quoted "2.9" is text: refused in one line naming file and field, never parsed."""
    doc = parse_document(text, suffix=suffix, source=f"x{suffix}")
    with pytest.raises(FileFormatError, match=match) as info:
        doc.array("H", kind="length")
    assert "\n" not in str(info.value)
    with pytest.raises(FileFormatError, match="string"):
        doc.array("H")  # also without a kind
    with pytest.raises(FileFormatError, match="string"):
        doc.float("H", kind="length")


def test_quoted_integer_and_sub_document_fields_are_named():
    doc = parse_document('rig:\n  count: "3"\n  items: [{x: "0.1"}]\n', source="x.yaml")
    with pytest.raises(FileFormatError, match=r"x.yaml: field 'rig.count': is a quoted string \('3'\), expected an integer"):
        doc.sub("rig").int("count")
    with pytest.raises(FileFormatError, match=r"x.yaml: field 'rig.items\[0\].x': is a quoted string \('0.1'\)"):
        doc.sub("rig").items_list("items")[0].float("x")


@pytest.mark.parametrize("text, value", [("1e3", 1e3), ("2E-3", 2e-3), ("1.0e3", 1e3), ("-.5e+2", -50.0), ("1_000e-3", 1.0),
                                         ("1.5", 1.5), ("0x10", 16.0), (".inf", np.inf)])
def test_unquoted_numbers_in_any_yaml_notation_are_numbers(text, value):
    # YAML 1.1 (PyYAML) would read '1e3' and '1.0e3' as text; written unquoted they are numbers
    doc = parse_document(f"H: {text}\n", source="x.yaml")
    assert doc.array("H", finite=False) == value
    assert parse_document(f'H: "{text}"\n').raw("H") == text  # quoted stays text


@pytest.mark.parametrize(
    "quantity, match",
    [
        ("{value: 2.9, unit: m, sigma: 0.1}",
         r"^x.yaml: field 'H': unknown key 'sigma' in a quantity mapping \(allowed: value, unit\)$"),
        ("{value: 2.9, units: m}",
         r"^x.yaml: field 'H': unknown key 'units' in a quantity mapping \(allowed: value, unit\); did you mean 'unit'\?$"),
        ("{valeu: 2.9, unit: m}", r"unknown key 'valeu' .*did you mean 'value'\?$"),
        ("{value: 2.9, unit: m, std: 0.1, note: x}", r"unknown keys 'std', 'note' in a quantity mapping \(allowed: value, unit\)$"),
    ],
)
def test_unknown_keys_in_a_quantity_mapping_are_refused(quantity, match):
    doc = parse_document(f"H: {quantity}\nP: [{quantity}]\n", source="x.yaml")
    with pytest.raises(FileFormatError, match=match):
        doc.float("H", kind="length")
    with pytest.raises(FileFormatError, match="unknown key"):
        doc.array("H")  # kind or not
    with pytest.raises(FileFormatError, match=r"field 'rig.H': unknown key"):
        parse_document(f"rig: {{H: {quantity}}}\n", source="x.yaml").sub("rig").float("H", kind="length")


_finite = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=150, deadline=None)
@given(_finite, st.sampled_from(["yaml-repr", "yaml-dump", "json"]))
def test_property_a_number_written_as_a_number_reads_back_exactly_and_quoted_is_refused(v, how):
    if how == "yaml-repr":
        number, quoted, suffix = f"H: {v!r}\n", f'H: "{v!r}"\n', ".yaml"
    elif how == "yaml-dump":
        number, quoted, suffix = yaml.safe_dump({"H": v}), f"H: '{v}'\n", ".yaml"
    else:
        number, quoted, suffix = json.dumps({"H": v}), json.dumps({"H": repr(v)}), ".json"
    assert parse_document(number, suffix=suffix).float("H") == v
    with pytest.raises(FileFormatError, match=r"field 'H': is a quoted string \('.*'\), expected a number"):
        parse_document(quoted, suffix=suffix, source=f"x{suffix}").float("H")


@settings(max_examples=100, deadline=None)
@given(st.lists(_finite, min_size=1, max_size=6), st.data())
def test_property_one_quoted_entry_is_named_by_its_index(values, data):
    i = data.draw(st.integers(0, len(values) - 1))
    raw = list(values)
    raw[i] = repr(values[i])
    doc = parse_document(json.dumps({"P": raw}), suffix=".json", source="x.json")
    with pytest.raises(FileFormatError, match=rf"x.json: field 'P': contains a quoted string .* at index \({i},\)"):
        doc.array("P")
    np.testing.assert_array_equal(parse_document(json.dumps({"P": values}), suffix=".json").array("P"), values)


@settings(max_examples=100, deadline=None)
@given(st.text(min_size=1, max_size=8).filter(lambda k: k not in ("value", "unit")), st.sampled_from([0.1, "m", None, [1]]))
def test_property_any_extra_quantity_key_is_named(key, extra):
    doc = parse_document(json.dumps({"H": {"value": 2.9, "unit": "m", key: extra}}), suffix=".json", source="x.json")
    with pytest.raises(FileFormatError, match=r"field 'H': unknown key") as info:
        doc.float("H", kind="length")
    assert repr(key) in str(info.value) and "(allowed: value, unit)" in str(info.value)


def test_null_is_reported_as_empty_not_as_nan():
    doc = parse_document("units: {length: m}\nH: null\nP: [[1, 2], [3, null]]\nQ: {value: null, unit: m}\n", source="x.yaml")
    with pytest.raises(FileFormatError, match=r"x.yaml: field 'H': is empty \(null\), expected a number"):
        doc.float("H", kind="length")
    with pytest.raises(FileFormatError, match=r"field 'H': is empty \(null\), expected an array of shape \(N, 2\)"):
        doc.array("H", kind="length", shape=("N", 2))
    with pytest.raises(FileFormatError, match=r"field 'P': contains an empty value \(null\) at index \(1, 1\)"):
        doc.array("P", kind="length")
    with pytest.raises(FileFormatError, match=r"field 'Q': is empty \(null\)"):
        doc.float("Q", kind="length")
    # where non-finite values are allowed, null is JSON's way to write a missing value
    assert np.isnan(doc.array("P", finite=False)[1, 1])


@pytest.mark.parametrize(
    "units, match",
    [
        ("cm", r"x.yaml: field 'units': must be a mapping of kind to unit, e.g. \{length: mm, angle: deg\}, got str \('cm'\)"),
        ("null", r"field 'units': must be a mapping of kind to unit.*got null"),
        ("[mm, deg]", r"field 'units': must be a mapping of kind to unit.*got list"),
        ("{angel: deg}", r"x.yaml: field 'units.angel': unknown kind 'angel' \(known: angle, angular_rate, .*length"),
        ("{length: deg}", r"field 'units.length': must be a unit of length \(m, cm, mm, um\), got 'deg' \(a unit of angle\)"),
        ("{length: furlong}", r"field 'units.length': unknown unit 'furlong' \(units of length: m, cm, mm, um\)"),
        ("{length: true}", r"field 'units.length': must be a unit of length \(m, cm, mm, um\), got bool \(True\)"),
    ],
)
def test_units_mapping_is_validated(units, match):
    doc = parse_document(f"units: {units}\nH: 290\nyaw: 90\n", source="x.yaml")
    with pytest.raises((FileFormatError, UnitError), match=match):
        doc.float("H", kind="length")
    with pytest.raises(RobocalError, match=match):  # also for inline quantities and for sub-documents
        parse_document(f"units: {units}\nrig: {{H: {{value: 2.9, unit: m}}}}\n", source="x.yaml").sub("rig").float("H", kind="length")


def test_units_errors_name_the_nested_field_and_free_text_units_still_load():
    doc = parse_document("rig:\n  units: {lenght: mm}\n  H: 290\n", source="x.yaml")
    with pytest.raises(UnitError, match=r"x.yaml: field 'rig.units.lenght': unknown kind 'lenght'"):
        doc.sub("rig").float("H", kind="length")
    # a result file's units map estimate names to units; a file may use 'units' as a note.
    # Neither is an error until a quantity is read through them.
    doc = parse_document("units: {t: m, R: '1'}\nt: [1, 2, 3]\n", source="result.yaml")
    np.testing.assert_allclose(doc.array("t"), [1, 2, 3])
    assert parse_document("units: rad for angles, m for lengths\nx: 1\n").raw("x") == 1
    good = parse_document("units: {length: mm, dimensionless: 1, angular_rate: deg/s}\nH: 290\n")
    assert good.units == {"length": "mm", "dimensionless": "1", "angular_rate": "deg/s"}


# -- mapping-shaped fuzzing: exercise the loader paths, not only the YAML parser --------

_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),  # unbounded: ints too large for a float
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=4),
    st.sampled_from(["m", "mm", "cm", "deg", "rad", "s", "px", "1", "furlong", "nan", "1e3"]),
)
_values = st.recursive(
    _scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.sampled_from(["value", "unit", "x"]), inner, max_size=3),
    max_leaves=12,
)
_units = st.one_of(
    st.dictionaries(st.sampled_from(["length", "angle", "time", "pixel", "angel", "speed"]),
                    st.sampled_from(["m", "mm", "deg", "s", "px", "m/s", "furlong"]) | _scalars, max_size=3),
    _values,
)
_point_lists = st.lists(st.lists(st.one_of(st.floats(-1e3, 1e3), _scalars), min_size=2, max_size=4), max_size=4)
_fields = {"units": _units, "points": _point_lists | _values, "H": _values, "count": _values, "name": _values, "flag": _values}
_documents = st.fixed_dictionaries(
    {},
    optional={
        **_fields,
        "rig": st.fixed_dictionaries({}, optional=_fields) | _values,
        "items": st.lists(st.fixed_dictionaries({}, optional=_fields) | _values, max_size=3) | _values,
    },
)


def _has(x, match):
    if isinstance(x, dict):
        return any(_has(v, match) for v in x.values())
    if isinstance(x, list):
        return any(_has(v, match) for v in x)
    return match(x)


def _exercise(doc):
    """Every accessor on ``doc``: a checked value or a RobocalError, never another exception."""
    for call in (
        lambda: doc.array("points", kind="length", shape=("N", 3)),
        lambda: doc.array("points", kind="length", shape=("N", 3), finite=False),
        lambda: doc.array("H"),
        lambda: doc.float("H", kind="length", positive=True),
        lambda: doc.float("H", kind="angle", default=0.5),
        lambda: doc.int("count", minimum=0),
        lambda: doc.str("name", choices=("a", "b")),
        lambda: doc.bool("flag", default=False),
    ):
        try:
            out = call()
        except RobocalError:
            continue
        if isinstance(out, np.ndarray):
            assert out.dtype == np.float64
    for key in ("points", "H"):
        # a value read as finite numbers is finite, and never came from a boolean
        try:
            arr = doc.array(key)
        except RobocalError:
            continue
        assert np.all(np.isfinite(arr))
        raw = doc.raw(key)
        if isinstance(raw, dict):
            assert set(raw) <= {"value", "unit"}  # no key of a quantity mapping is silently ignored
        value = raw["value"] if isinstance(raw, dict) else raw
        assert not _has(value, lambda v: isinstance(v, bool))
        assert not _has(value, lambda v: isinstance(v, str))  # nor was a number read from text
    try:
        pts = doc.array("points", kind="length", shape=("N", 3))
    except RobocalError:
        pass
    else:
        assert pts.ndim == 2 and pts.shape[1] == 3


@settings(max_examples=200, deadline=None)
@given(_documents, st.sampled_from([".yaml", ".json"]))
def test_fuzz_mapping_shaped_documents_give_values_or_robocal_errors(data, suffix):
    text = json.dumps(data) if suffix == ".json" else yaml.safe_dump(data)
    doc = parse_document(text, suffix=suffix, source=f"fuzz{suffix}")  # a mapping always parses
    _exercise(doc)
    for sub in ("rig", "items"):
        try:
            docs = [doc.sub(sub)] if sub == "rig" else doc.items_list(sub)
        except RobocalError:
            continue
        for d in docs:
            _exercise(d)


def test_a_column_without_a_unit_gets_a_hint_of_its_own_kind(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("t,x [mm]\n0,1\n1,2\n")
    tab = load_csv(p)
    with pytest.raises(UnitError, match=r"needs a unit of time in its header, e.g. 't \[s\]'"):
        tab.column("t", kind="time")
    with pytest.raises(UnitError, match=r"e.g. 't \[rad\]'"):
        tab.column("t", kind="angle")


def test_an_unquoted_dimensionless_unit_reads_like_the_units_mapping():
    doc = parse_document("k: {value: 2.5, unit: 1}\nj: 3.0\nunits: {dimensionless: 1}\n")
    assert doc.array("k", kind="dimensionless") == 2.5
    assert doc.array("j", kind="dimensionless") == 3.0
    with pytest.raises(UnitError, match="unknown unit '2'"):
        parse_document("k: {value: 2.5, unit: 2}\n").array("k", kind="dimensionless")


def test_require_known_keys_names_the_first_unknown_key_and_the_closest_known_one():
    doc = parse_document("H: 2.9\ntilt_mim: 10\n", source="p.yaml")
    with pytest.raises(FileFormatError, match=r"p.yaml: field 'tilt_mim': unknown key \(did you mean 'tilt_min'\?\); "
                                              r"known keys: H, tilt_min"):
        doc.require_known_keys(("H", "tilt_min"))
    with pytest.raises(FileFormatError, match=r"field 'tilt_mim': unknown key; known keys: H$"):
        doc.require_known_keys(("H",))
    doc.require_known_keys(("H", "tilt_mim"))


@pytest.mark.parametrize("text, suffix, says", [
    ("H: 2.9\nroom:\n  H: 1\nW: 3\n\nH: 3.1\n", ".yaml", "key 'H' appears twice (lines 1 and 6)"),
    ("points: {a: 1, a: 2}\n", ".yaml", "key 'a' appears twice (lines 1 and 1)"),
    ('{"H": 2.9,\n "room": {"H": 1},\n "H": 3.1}\n', ".json", "key 'H' appears twice (lines 1 and 3)"),
])
def test_a_duplicate_key_is_an_error_naming_the_key_and_both_lines(tmp_path, text, suffix, says):
    f = tmp_path / f"room{suffix}"
    f.write_text(text)
    with pytest.raises(FileFormatError) as e:
        load_document(f)
    assert str(e.value) == f"{f}: {says}; keep one"


def test_keys_repeated_in_different_mappings_or_by_a_merge_are_not_duplicates():
    doc = parse_document("a: {H: 1}\nb: {H: 2}\nbase: &b {x: 1}\nd:\n  <<: *b\n  x: 2\n")
    assert doc.data["d"] == {"x": 2} and doc.data["a"] == {"H": 1}


@given(st.lists(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64), min_size=3, max_size=3),
                min_size=0, max_size=20),
       st.sampled_from(["{:r}", " {:r} ", "{:.17g}", "{:.17e}"]))
def test_csv_fast_and_quoted_paths_read_the_same_numbers(rows, fmt):
    # Files without quotes go through NumPy's C reader, files with a quoted cell
    # through the csv module; both must give Python float()'s value of every cell
    # (repr and %.17g round-trip a double exactly, so the comparison is exact).
    fmt = fmt.replace("{:r}", "{!r}")
    body = "".join(",".join(fmt.format(v) for v in r) + "\n" for r in rows)
    plain = load_csv("plain.csv", text="a [m],b,c\n" + body)
    quoted = load_csv("quoted.csv", text='a [m],"b",c\n' + body)
    want = np.array(rows, dtype=float).reshape(-1, 3)
    for j, name in enumerate("abc"):
        np.testing.assert_array_equal(plain.column(name), want[:, j])
        np.testing.assert_array_equal(quoted.column(name), want[:, j])
    assert list(plain.lines) == list(quoted.lines) == list(range(2, 2 + len(rows)))


def test_csv_cells_numpy_refuses_but_float_reads_take_the_careful_path():
    table = load_csv("u.csv", text="a,b\n1_000,2\n")  # float("1_000") == 1000.0
    assert table.column("a")[0] == 1000.0
    with pytest.raises(FileFormatError, match=r"row 2 \(line 4\), column 'b': not a number: '2 # note'"):
        load_csv("c.csv", text="a,b\n1,2\n# comment line\n3,2 # note\n")
