"""Runs don't mix: each --out folder records its run, a stale or half-made result is never read as new."""

import json
import os

import pytest

import robocal.cli.main as m
from robocal.cli._common import prepare_out_dir
from robocal.errors import FileFormatError, InputError
from robocal.workflow import Command, Option, Workflow
from robocal.io import INCOMPLETE, MANIFEST, CalibrationResult, atomic_write_bytes, atomic_write_text, load_result, \
    read_manifest, write_result


def _writer_rig(name="toy"):
    """A rig with two commands writing the files named on the command line."""

    options = (Option("input", nargs="?", default=None), Option("--files", default="result.json"),
               Option("--then", choices=["ok", "error", "interrupt"], default="ok"),
               Option("--over", default=None, help="also write this path"))
    return Workflow(name, "writes files", "writes files", commands=tuple(
        Command(cmd, "writes files", run=lambda a, cmd=cmd: _write(a, f"{name}-{cmd}"), options=options)
        for cmd in ("first", "second")))


def _write(args, label):
    print("working")  # the expensive part a command does before it claims its folder
    out = prepare_out_dir(args.out, label)
    for f in filter(None, args.files.split(",")):
        if f == "result.json":
            write_result(out / f, CalibrationResult(rig="toy", method="m", estimate={"x": 1.0}))
        else:
            atomic_write_text(out / f, "data\n")
    if args.over:
        atomic_write_text(args.over, "replaced\n")
    if args.then == "error":
        raise InputError("field 'x': must be > 0, got -1", source="toy.yaml")
    if args.then == "interrupt":
        raise KeyboardInterrupt
    return 0


@pytest.fixture
def run(monkeypatch, capsys):
    monkeypatch.setattr(m, "discover_rigs", lambda names=None: [_writer_rig(), _writer_rig("other")])

    def _run(*argv):
        code = m.main([str(a) for a in argv])
        out, err = capsys.readouterr()
        return code, out, err

    return _run


def _listing(folder):
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def test_a_finished_run_lists_its_files_and_leaves_no_marker(tmp_path, run):
    out = tmp_path / "cal"
    code, _, err = run("toy", "first", "--files", "result.json,sub/a.csv", "--out", out)
    assert code == 0, err
    assert not (out / INCOMPLETE).exists()
    man = read_manifest(out)
    assert man["state"] == "complete" and man["label"] == "toy-first" and man["rig"] == "toy"
    assert man["command"] == "robocal toy first" and "--out" in man["command_line"]
    assert man["files"] == ["result.json", "sub/a.csv"]
    assert man["started"] <= man["finished"]
    assert load_result(out / "result.json").estimate == {"x": 1.0}


def test_a_rerun_of_the_same_command_removes_the_earlier_runs_files_first(tmp_path, run):
    out = tmp_path / "path"
    assert run("toy", "first", "--files", "result.json,commands_A.csv,commands_B.csv", "--out", out)[0] == 0
    code, stdout, _ = run("toy", "first", "--files", "result.json,commands_A.csv", "--out", out)
    assert code == 0
    # the stale commands_B.csv of the earlier run does not survive (issue 18)
    assert _listing(out) == [MANIFEST, "commands_A.csv", "result.json"]
    assert "removed the 3 file(s) of the earlier `robocal toy first` run" in stdout


def test_another_commands_folder_is_refused_in_one_line_naming_it_and_the_fix(tmp_path, run):
    out = tmp_path / "sim"
    run("toy", "first", "--files", "run.yaml,images/a.png,images/b.png", "--out", out)
    before = _listing(out)
    for argv in (("toy", "second"), ("other", "first")):
        code, stdout, err = run(*argv, "--out", out)
        assert code == 2 and "working" not in stdout  # refused before the work, not after it
        assert err.count("\n") == 1 and err.startswith("robocal: error: --out: ")
        assert "holds the files of a `robocal toy first` run (images/, run.yaml)" in err
        assert "choose another folder or add --force" in err
        assert _listing(out) == before


def test_force_replaces_another_run_but_keeps_files_robocal_did_not_write(tmp_path, run):
    out = tmp_path / "cal"
    run("toy", "first", "--files", "run.yaml,x.csv", "--out", out)
    (out / "notes.txt").write_text("mine\n")
    code, _, err = run("toy", "second", "--out", out)
    assert code == 2 and "files robocal did not write (notes.txt)" in err
    code, stdout, err = run("toy", "second", "--out", out, "--force")
    assert code == 0, err
    assert _listing(out) == [MANIFEST, "notes.txt", "result.json"]
    assert (out / "notes.txt").read_text() == "mine\n"
    man = read_manifest(out)
    assert man["files"] == ["result.json"] and man["kept"] == ["notes.txt"]
    # a kept file is not overwritten either
    code, _, err = run("toy", "second", "--files", "notes.txt", "--out", out)
    assert code == 2 and "refusing to write over" in err and "notes.txt" in err
    assert (out / "notes.txt").read_text() == "mine\n"


def test_unknown_files_alone_are_refused_and_force_writes_beside_them(tmp_path, run):
    out = tmp_path / "here"
    out.mkdir()
    (out / "room.yaml").write_text("H: 1\n")
    code, _, err = run("toy", "first", "--out", out)
    assert code == 2 and "files robocal did not write (room.yaml)" in err and "--force" in err
    assert run("toy", "first", "--out", out, "--force")[0] == 0
    # the same command again keeps what the --force run kept, without asking again
    assert run("toy", "first", "--out", out)[0] == 0
    assert (out / "room.yaml").read_text() == "H: 1\n"


def test_a_command_never_writes_over_its_own_input(tmp_path, run):
    inp = tmp_path / "room.yaml"
    inp.write_text("H: 1\n")
    code, _, err = run("toy", "first", inp, "--over", inp, "--out", tmp_path / "cal")
    assert code == 2 and err.count("\n") == 1
    assert f"refusing to write over {inp}: it is an input of this command" in err
    assert inp.read_text() == "H: 1\n"


def test_force_never_removes_an_input_of_the_command(tmp_path, run):
    sim = tmp_path / "sim"
    run("toy", "first", "--files", "run.yaml", "--out", sim)
    code, _, err = run("toy", "second", sim / "run.yaml", "--out", sim, "--force")
    assert code == 2 and "run.yaml, an input of this command" in err
    assert (sim / "run.yaml").is_file()


@pytest.mark.parametrize("how", ["error", "interrupt"])
def test_a_failed_or_interrupted_run_leaves_incomplete_and_its_result_is_refused(tmp_path, run, how):
    out = tmp_path / "cal"
    assert run("toy", "first", "--out", out)[0] == 0
    code, _, err = run("toy", "first", "--then", how, "--out", out)
    assert code == (2 if how == "error" else 130)
    assert (out / INCOMPLETE).is_file()
    man = read_manifest(out)
    assert man["state"] == "failed" and man["files"] == ["result.json"]
    with pytest.raises(FileFormatError, match="not a finished result: the `robocal toy first` run .* failed"):
        load_result(out / "result.json")
    assert load_result(out / "result.json", allow_incomplete=True).estimate == {"x": 1.0}
    # a later command reading it gets the same one line
    code, _, err = run("toy", "second", out / "result.json", "--out", tmp_path / "eval")
    assert code == 0  # the toy does not read its input; the marker is for readers
    # the same command again cleans up and finishes
    assert run("toy", "first", "--out", out)[0] == 0
    assert not (out / INCOMPLETE).exists() and read_manifest(out)["state"] == "complete"


def test_a_failed_run_that_wrote_nothing_leaves_no_folder_it_made(tmp_path, run, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # the default time-stamped folder and a new --out: gone with the error
    code, _, err = run("toy", "first", "--files", "", "--then", "error")
    assert code == 2 and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
    assert run("toy", "first", "--files", "", "--then", "error", "--out", tmp_path / "new")[0] == 2
    assert not (tmp_path / "new").exists()
    # a folder that existed before the run stays, with the record of the failure
    (tmp_path / "mine").mkdir()
    assert run("toy", "first", "--files", "", "--then", "error", "--out", tmp_path / "mine")[0] == 2
    assert read_manifest(tmp_path / "mine")["state"] == "failed" and (tmp_path / "mine" / INCOMPLETE).is_file()


def test_a_killed_run_that_recorded_no_files_still_owns_them(tmp_path, run):
    out = tmp_path / "cal"
    run("toy", "first", "--files", "result.json,a.csv", "--out", out)
    man = read_manifest(out)
    # what a SIGKILL leaves: the manifest still says running, no file list, the marker
    (out / MANIFEST).write_text(json.dumps({**man, "state": "running", "files": None, "finished": None}))
    (out / INCOMPLETE).write_text("")
    assert run("toy", "first", "--files", "result.json", "--out", out)[0] == 0
    assert _listing(out) == [MANIFEST, "result.json"]


def test_prepare_out_dir_from_the_python_api_only_makes_the_folder(tmp_path):
    out = prepare_out_dir(tmp_path / "a" / "b", "toy-first")
    assert out.is_dir() and not any(out.iterdir())
    (out / "x.txt").write_text("x")
    assert prepare_out_dir(out, "other") == out  # no run open: no refusal either


def _refuse_temporary_files(monkeypatch):
    """The atomic writer's temporary file cannot be made: a folder without write permission."""
    from robocal.io import _atomic

    def refuse(path):
        raise PermissionError(13, "Permission denied", os.path.join(path.parent, f".{path.name}.1.2.0.tmp"))

    monkeypatch.setattr(_atomic, "_create_temporary", refuse)


def test_the_writer_names_the_users_folder_not_its_temporary_file(tmp_path, monkeypatch):
    _refuse_temporary_files(monkeypatch)
    with pytest.raises(PermissionError) as e:
        atomic_write_bytes(tmp_path / "out" / "result.json", b"{}")
    assert e.value.filename == str(tmp_path / "out")
    assert ".tmp" not in str(e.value) and "result.json" in str(e.value)


def test_an_unwritable_out_is_one_line_naming_the_folder(tmp_path, run, monkeypatch):
    _refuse_temporary_files(monkeypatch)
    out = tmp_path / "ro"
    code, _, err = run("toy", "first", "--out", out)
    assert code == 2 and err.count("\n") == 1 and ".tmp" not in err
    assert f"cannot write into {out}" in err


def test_an_out_below_a_file_is_refused_before_the_work(tmp_path, run):
    (tmp_path / "plain").write_text("x\n")
    code, stdout, err = run("toy", "first", "--out", tmp_path / "plain" / "out")
    assert code == 2 and "working" not in stdout and err.count("\n") == 1
    assert "plain is a file" in err
