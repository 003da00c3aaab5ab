"""The batch manifest: YAML and CSV, and each malformed one refused in one line naming the file and field."""

import pytest

from robocal.batch import load_manifest
from robocal.errors import FileFormatError


def test_yaml_and_csv_give_the_same_entries(tmp_path):
    (tmp_path / "m.yaml").write_text("rig: humanoid\noptions: {params: seed}\ndatasets:\n"
                                     "  - {id: nao-01, input: a/run.yaml}\n"
                                     "  - {id: nao-02, inputs: [b/run.yaml], options: {params: all}}\n")
    (tmp_path / "m.csv").write_text("# the fleet of the lab\nid,input\nnao-01,a/run.yaml\nnao-02,b/run.yaml\n")
    y = load_manifest(tmp_path / "m.yaml", rig="humanoid")
    c = load_manifest(tmp_path / "m.csv", rig="humanoid")
    assert [e.id for e in y] == [e.id for e in c] == ["nao-01", "nao-02"]
    assert [e.inputs for e in y] == [e.inputs for e in c] == [(tmp_path / "a/run.yaml",), (tmp_path / "b/run.yaml",)]
    assert y[0].options == {"params": "seed"} and y[1].options == {"params": "all"}  # own options win
    two = tmp_path / "two.csv"
    two.write_text("id,input,input2\nrobot-1,g.csv,t.csv\n")
    assert load_manifest(two)[0].inputs == (tmp_path / "g.csv", tmp_path / "t.csv")


@pytest.mark.parametrize("text,match", [
    ("datasets:\n  - {id: a, input: x.yaml}\n  - {id: A, input: y.yaml}\n", "used twice"),
    ("datasets:\n  - {id: ../up, input: x.yaml}\n", "letters, digits"),
    ("datasets:\n  - {id: .hidden, input: x.yaml}\n", "not starting with"),
    ("datasets:\n  - {id: a, input: x.yaml, inptus: [y]}\n", "did you mean"),
    ("datasets:\n  - {id: a}\n", "exactly one of 'input'"),
    ("datasets: []\n", "is empty"),
    ("rig: mirror\ndatasets:\n  - {id: a, input: x.yaml}\n", "for rig 'mirror', the command runs 'humanoid'"),
    ("datasets:\n  - {id: a, input: x.yaml, options: 3}\n", "options"),
])
def test_bad_yaml_manifests_are_one_line(tmp_path, text, match):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    with pytest.raises(FileFormatError, match=match) as exc:
        load_manifest(path, rig="humanoid")
    assert "\n" not in str(exc.value) and "m.yaml" in str(exc.value)


@pytest.mark.parametrize("text,match", [
    ("", "empty"),
    ("name,file\na,b\n", "header must be 'id,input'"),
    ("id,input\n", "no data set"),
    ("id,input\na,x.yaml,extra\n", "row 2: 3 cells"),
    ("id,input\na,\n", "row 2: input is empty"),
])
def test_bad_csv_manifests_are_one_line(tmp_path, text, match):
    path = tmp_path / "m.csv"
    path.write_text(text)
    with pytest.raises(FileFormatError, match=match) as exc:
        load_manifest(path)
    assert "m.csv" in str(exc.value)


def test_a_manifest_of_another_kind_is_refused(tmp_path):
    (tmp_path / "m.txt").write_text("id,input\n")
    with pytest.raises(FileFormatError, match="got '.txt'"):
        load_manifest(tmp_path / "m.txt")
