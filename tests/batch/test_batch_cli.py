"""``robocal batch``: a real rig end to end, bad arguments in one line, and no Dask behind ``robocal --help``."""

import json
import subprocess
import sys

import pytest

from robocal.cli.main import main


def test_batch_of_a_real_rig_with_a_missing_data_set(tmp_path, capsys):
    assert main(["handeye", "simulate", "--poses", "8", "--seed", "3", "--out", str(tmp_path / "sim")]) == 0
    (tmp_path / "fleet.csv").write_text("id,input,input2\n"
                                        "arm-1,sim/gripper_poses.csv,sim/target_poses.csv\n"
                                        "arm-2,missing/gripper_poses.csv,sim/target_poses.csv\n")
    capsys.readouterr()
    code = main(["batch", "handeye", str(tmp_path / "fleet.csv"), "--workers", "1", "--out", str(tmp_path / "cal")])
    out, err = capsys.readouterr()
    assert code == 1  # one data set failed: the batch ran, and says so in its status
    assert "batch: 1 of 2 data set(s) calibrated, 1 failed (arm-2)" in out
    assert "arm-2:" in err and "gripper_poses.csv" in err and "Traceback" not in err
    assert (tmp_path / "cal" / "arm-1" / "result.json").is_file() and (tmp_path / "cal" / "arm-1" / "report.html").is_file()
    run = json.loads((tmp_path / "cal" / ".robocal-run.json").read_text())
    assert run["state"] == "complete" and not (tmp_path / "cal" / "INCOMPLETE").exists()
    # the per-arm result is a robocal result like any other: robocal report rebuilds its page
    assert main(["report", str(tmp_path / "cal" / "arm-1" / "result.json"), "--out", str(tmp_path / "rep")]) == 0
    # --resume keeps arm-1 (its folder's run manifest says complete); without it the batch starts over
    capsys.readouterr()
    assert main(["batch", "handeye", str(tmp_path / "fleet.csv"), "--workers", "1", "--resume", "--no-fleet",
                 "--out", str(tmp_path / "cal")]) == 1
    assert "1 complete from an earlier run" in capsys.readouterr().out


@pytest.mark.parametrize("argv,match", [
    (["batch", "nosuchrig", "M.csv", "--out", "X"], "'nosuchrig' is not an installed rig"),
    (["batch", "handeye", "M.csv", "--workers", "0", "--out", "X"], "--workers: must be >= 1, got 0"),
    (["batch", "handeye", "M.csv", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1", "--out", "X"],
     "exclude each other"),
    (["batch", "handeye", "M.txt", "--out", "X"], "got '.txt'"),
])
def test_bad_arguments_are_one_line(tmp_path, capsys, monkeypatch, argv, match):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "M.csv").write_text("id,input,input2\na,g.csv,t.csv\n")
    (tmp_path / "M.txt").write_text("")
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own usage errors
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1


def test_help_imports_no_dask():
    code = ("import sys\nfrom robocal.cli.main import main\n"
            "for argv in (['--help'], ['batch', '--help']):\n"
            "    try:\n        main(argv)\n    except SystemExit:\n        pass\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')), file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert "robocal batch" not in out.stderr and out.stderr.strip().splitlines()[-1] == "[]"
    assert "--scheduler ADDRESS" in out.stdout
