"""``robocal._metadata``: the version and the rigs' entry points from a cache that is rebuilt whenever stale."""

import json
import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

import robocal._metadata as md


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOCAL_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("ROBOCAL_NO_CACHE", raising=False)
    md.forget()
    yield tmp_path / "cache"
    md.forget()


def _truth():
    return sorted((ep.name, ep.value) for ep in metadata.entry_points(group=md.RIG_GROUP)), metadata.version("robocal")


def _answer():
    md.forget()
    return sorted((ep.name, ep.value) for ep in md.entry_points()), md.version()


def test_the_cached_answer_is_importlib_metadatas(cache_dir):
    assert _answer() == _truth()
    (path,) = cache_dir.iterdir()
    assert path == md.cache_path()
    assert _answer() == _truth()  # now read from the file


def test_the_launcher_and_python_m_share_one_cache_and_skip_importlib_metadata(cache_dir):
    """``robocal`` (sys.path[0] = bin/, shebang bin/python3) and ``python -c`` (sys.path[0] = '') hit one file."""
    launcher = [str(Path(sys.executable).parent / "robocal")]
    if not Path(launcher[0]).is_file():  # not installed with its launcher: the module's own entry
        launcher = [sys.executable, "-m", "robocal"]
    env = {**os.environ, "ROBOCAL_CACHE_DIR": str(cache_dir)}
    subprocess.run([*launcher, "--version"], env=env, check=True, capture_output=True)
    code = ("import json, sys, robocal, robocal.cli._rig as r\n"
            "names = r.registered_rig_names(); v = robocal.__version__\n"
            "print(json.dumps([names, v, 'importlib.metadata' in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    names, version, imported = json.loads(out.stdout)
    assert (names, version) == (sorted(n for n, _ in _truth()[0]), _truth()[1])
    assert imported is False
    assert len(list(cache_dir.iterdir())) == 1


def test_another_search_path_keeps_its_own_cache_file(cache_dir, monkeypatch):
    """pytest, or a checkout on PYTHONPATH, between two commands: each keeps its answer, neither is rewritten."""
    md.entry_points()
    path = md.cache_path()
    written = path.stat().st_mtime_ns
    monkeypatch.setattr(sys, "path", [*sys.path, str(cache_dir.parent / "elsewhere")])
    assert md.cache_path() != path
    assert _answer() == _truth()
    monkeypatch.undo()
    monkeypatch.setenv("ROBOCAL_CACHE_DIR", str(cache_dir))
    assert md.cache_path() == path and path.stat().st_mtime_ns == written
    assert md._load_cache(path) is not None  # still valid for the first search path: no importlib.metadata


def test_the_cache_is_used_while_its_key_holds_and_rebuilt_when_it_changes(cache_dir):
    md.entry_points()
    path = md.cache_path()
    doc = json.loads(path.read_text())
    doc["version"] = "9.9.9-planted"
    path.write_text(json.dumps(doc))
    assert _answer()[1] == "9.9.9-planted"  # the key holds: the file is the answer
    doc["key"][0][1] = (doc["key"][0][1] or 0) - 1  # as if a sys.path folder changed (pip install/uninstall)
    path.write_text(json.dumps(doc))
    assert _answer() == _truth()
    assert json.loads(path.read_text())["version"] == _truth()[1]  # rewritten


def test_files_written_in_the_current_folder_do_not_invalidate_the_cache(tmp_path, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setattr(sys, "path", [str(work), *sys.path])  # what `python -m robocal` puts first
    before = md._key([])
    (work / "out").mkdir()  # a command's --out folder
    assert md._key([]) == before
    assert str(work) not in json.dumps(before)
    monkeypatch.setattr(sys, "path", [str(tmp_path / "venv" / "bin"), *sys.path[1:]])  # the robocal launcher's
    assert md._key([]) == before  # the same install run both ways shares one cache


@pytest.mark.parametrize("text", ["", "{not json", "[]", '{"schema": "robocal.metadata-cache/1"}',
                                  '{"schema": "robocal.metadata-cache/1", "version": 3, "rigs": [], "files": [], "key": []}'])
def test_a_corrupt_cache_is_rebuilt(cache_dir, text):
    path = md.cache_path()
    path.parent.mkdir(parents=True)
    path.write_text(text)
    assert _answer() == _truth()
    assert json.loads(path.read_text())["schema"] == "robocal.metadata-cache/1"


def test_an_unwritable_cache_folder_is_ignored(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache folder should be")
    monkeypatch.setenv("ROBOCAL_CACHE_DIR", str(blocker / "robocal"))
    md.forget()
    try:
        assert _answer() == _truth()
    finally:
        md.forget()


def test_no_cache_when_asked(cache_dir, monkeypatch):
    monkeypatch.setenv("ROBOCAL_NO_CACHE", "1")
    assert md.cache_path() is None
    assert _answer() == _truth()
    assert not cache_dir.exists()


def test_entry_point_load_follows_the_value():
    ep = md.EntryPoint("x", "robocal.errors:RobocalError", md.RIG_GROUP)
    from robocal.errors import RobocalError

    assert ep.load() is RobocalError
    with pytest.raises(ModuleNotFoundError):
        md.EntryPoint("y", "robocal_no_such_module.cli:RIG", md.RIG_GROUP).load()
