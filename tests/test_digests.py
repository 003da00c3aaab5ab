"""``robocal._digests``: a large input's SHA-256 reused between commands only while the file is unchanged."""

import hashlib
import json
import os

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robocal._digests as dg
from robocal.io import hash_inputs, sha256_file


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private cache, files of 1 kB and up cached, and every file 'settled' (the test writes and hashes
    within milliseconds; the real rule wants its last change 2 s before hashing starts)."""
    monkeypatch.setenv("ROBOCAL_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("ROBOCAL_NO_CACHE", raising=False)
    monkeypatch.setattr(dg, "MIN_BYTES", 1000)
    monkeypatch.setattr(dg, "SETTLE_NS", -10**12)
    return tmp_path / "cache"


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _entries(cache):
    return sorted((cache / "sha256").glob("*.json")) if (cache / "sha256").is_dir() else []


def test_a_large_files_digest_is_stored_and_reused(cache, tmp_path, monkeypatch):
    f = tmp_path / "frames.bin"
    f.write_bytes(os.urandom(5000))
    assert sha256_file(f) == _digest(f.read_bytes())
    (entry,) = _entries(cache)
    doc = json.loads(entry.read_text())
    assert doc["path"] == os.path.realpath(f) and doc["sha256"] == _digest(f.read_bytes())

    def no_hashing(path):
        raise AssertionError("hashed again although unchanged")

    monkeypatch.setattr(dg, "_hash", no_hashing)
    assert hash_inputs([f]) == {str(f): doc["sha256"]}   # robocal.io's hash_inputs goes through the cache


def test_new_content_of_the_same_size_and_mtime_is_hashed_again(cache, tmp_path):
    """The slip the ctime in the key catches: a tool writes new bytes and puts the old mtime back (``rsync
    -t``, ``touch -d``, a copy with ``cp -p``): size and mtime match the entry, the content does not."""
    f = tmp_path / "frames.bin"
    f.write_bytes(b"a" * 5000)
    old = sha256_file(f)
    st0 = os.stat(f)
    f.write_bytes(b"b" * 5000)
    os.utime(f, ns=(st0.st_atime_ns, st0.st_mtime_ns))
    if os.stat(f).st_ctime_ns == st0.st_ctime_ns:
        pytest.skip("the file system's clock did not tick between two writes")
    assert os.stat(f).st_size == st0.st_size and os.stat(f).st_mtime_ns == st0.st_mtime_ns
    assert sha256_file(f) == _digest(b"b" * 5000) != old


def test_a_file_replaced_by_another_is_hashed_again(cache, tmp_path):
    f, g = tmp_path / "frames.bin", tmp_path / "other.bin"
    f.write_bytes(b"a" * 5000)
    sha256_file(f)
    g.write_bytes(b"c" * 5000)
    os.replace(g, f)
    assert sha256_file(f) == _digest(b"c" * 5000)


def test_nothing_is_stored_for_a_file_changed_just_now_or_while_hashed(cache, tmp_path, monkeypatch):
    f = tmp_path / "frames.bin"
    f.write_bytes(b"a" * 5000)
    monkeypatch.setattr(dg, "SETTLE_NS", 2_000_000_000)   # the real rule: this file changed < 2 s ago
    assert sha256_file(f) == _digest(b"a" * 5000)
    assert _entries(cache) == []

    monkeypatch.setattr(dg, "SETTLE_NS", -10**12)
    real_hash = dg._hash

    def hash_then_append(path):       # another process appends while this one hashes
        digest = real_hash(path)
        with open(path, "ab") as fh:
            fh.write(b"more")
        return digest

    monkeypatch.setattr(dg, "_hash", hash_then_append)
    assert sha256_file(f) == _digest(b"a" * 5000)      # what was read, used for this call only
    assert _entries(cache) == []
    monkeypatch.setattr(dg, "_hash", real_hash)
    assert sha256_file(f) == _digest(b"a" * 5000 + b"more")


def test_small_files_damaged_entries_and_no_cache(cache, tmp_path, monkeypatch):
    small = tmp_path / "run.yaml"
    small.write_bytes(b"x" * 999)
    assert sha256_file(small) == _digest(b"x" * 999) and _entries(cache) == []

    f = tmp_path / "frames.bin"
    f.write_bytes(b"a" * 5000)
    sha256_file(f)
    (entry,) = _entries(cache)
    for damage in ("{not json", json.dumps({"schema": "other"}), json.dumps([1, 2])):
        entry.write_text(damage)
        assert sha256_file(f) == _digest(b"a" * 5000)      # ignored and rewritten
        assert json.loads(entry.read_text())["sha256"] == _digest(b"a" * 5000)
    doc = json.loads(entry.read_text())
    entry.write_text(json.dumps({**doc, "sha256": "0" * 64, "path": str(tmp_path / "elsewhere")}))
    assert sha256_file(f) == _digest(b"a" * 5000)          # an entry for another path is not this file's

    monkeypatch.setenv("ROBOCAL_NO_CACHE", "1")
    g = tmp_path / "g.bin"
    g.write_bytes(b"g" * 5000)
    assert sha256_file(g) == _digest(b"g" * 5000) and len(_entries(cache)) == 1


def test_a_cache_that_cannot_be_written_is_not_used(tmp_path, monkeypatch):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setenv("ROBOCAL_CACHE_DIR", str(blocker))
    monkeypatch.delenv("ROBOCAL_NO_CACHE", raising=False)
    monkeypatch.setattr(dg, "MIN_BYTES", 1000)
    monkeypatch.setattr(dg, "SETTLE_NS", -10**12)
    f = tmp_path / "frames.bin"
    f.write_bytes(b"a" * 5000)
    assert sha256_file(f) == sha256_file(f) == _digest(b"a" * 5000)
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


@settings(max_examples=25, deadline=None)
@given(st.lists(st.binary(min_size=900, max_size=1100), min_size=1, max_size=4))
def test_every_call_gives_the_contents_digest(tmp_path_factory, contents):
    """Whatever sequence of contents a file goes through (sizes either side of the threshold), each call
    answers the digest of what the file holds then."""
    folder = tmp_path_factory.mktemp("d")
    env = {"ROBOCAL_CACHE_DIR": str(folder / "cache")}
    with pytest.MonkeyPatch.context() as mp:
        for k, v in env.items():
            mp.setenv(k, v)
        mp.delenv("ROBOCAL_NO_CACHE", raising=False)
        mp.setattr(dg, "MIN_BYTES", 1000)
        f = folder / "f.bin"
        for data in contents:
            f.write_bytes(data)
            assert sha256_file(f) == _digest(data)
