"""Key files (issue 25, item 2): written through a fresh exclusive temporary file, so a
leftover or planted ``NAME.key.tmp`` decides nothing; a private key that is a symlink or
readable by others is refused at load, in one line saying which file and ``chmod 600``."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest
from sensornet.peers.member_keys import SecurityError, check_private, make_keys
from sensornet.peers.security import Security

from sensornet.cli import main

MEMBERS = ["world", "s1", "s2", "s3"]
PRIVATE = ["ca.key", *(f"{m}{x}" for m in MEMBERS for x in (".key", ".ed25519"))]


def _mode(path: Path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def _keys(folder: Path) -> Path:
    make_keys("net1", MEMBERS, folder)
    return folder


def test_leftover_tmp_files_do_not_make_keys_readable(tmp_path):
    folder = tmp_path / "k"
    folder.mkdir()
    for name in ("ca.key.tmp", "s1.key.tmp", "s1.ed25519.tmp", "world.key.tmp"):
        (folder / name).write_bytes(b"")
        os.chmod(folder / name, 0o644)
    _keys(folder)
    for name in PRIVATE:
        assert _mode(folder / name) == 0o600, name
    for name in ("ca.pem", "s1.pem", "members.json"):
        assert _mode(folder / name) == 0o644, name
    assert (folder / "s1.key.tmp").read_bytes() == b""  # not used
    assert not [p.name for p in folder.iterdir() if p.name.startswith(".")]  # none left over


def test_a_planted_tmp_symlink_does_not_receive_a_key(tmp_path):
    folder = tmp_path / "k"
    folder.mkdir()
    victim = tmp_path / "victim"
    victim.write_text("mine\n")
    (folder / "s2.key.tmp").symlink_to(victim)
    (folder / "s2.ed25519.tmp").symlink_to(victim)
    _keys(folder)
    assert victim.read_text() == "mine\n"
    assert (folder / "s2.key.tmp").is_symlink()
    assert not (folder / "s2.key").is_symlink() and _mode(folder / "s2.key") == 0o600
    assert b"PRIVATE KEY" in (folder / "s2.key").read_bytes()
    Security.load(folder, "s2", "net1", MEMBERS[1:]).signer()  # the keys are s2's, usable


@pytest.mark.parametrize("name", ["s1.key", "s1.ed25519"])
@pytest.mark.parametrize("mode", [0o644, 0o640, 0o604, 0o660])
def test_a_private_key_readable_by_others_is_refused(tmp_path, name, mode):
    folder = _keys(tmp_path / "k")
    os.chmod(folder / name, mode)
    with pytest.raises(SecurityError) as info:
        Security.load(folder, "s1", "net1", MEMBERS[1:]).signer()
    msg = str(info.value)
    assert "\n" not in msg and str(folder / name) in msg and f"chmod 600 {folder / name}" in msg
    assert f"{mode:04o}" in msg
    os.chmod(folder / name, 0o600)
    Security.load(folder, "s1", "net1", MEMBERS[1:]).signer()  # fixed: accepted


@pytest.mark.parametrize("name", ["s1.key", "s1.ed25519"])
def test_a_private_key_that_is_a_symlink_is_refused(tmp_path, name):
    folder = _keys(tmp_path / "k")
    real = tmp_path / "elsewhere"
    (folder / name).rename(real)
    (folder / name).symlink_to(real)
    with pytest.raises(SecurityError, match="symbolic link") as info:
        Security.load(folder, "s1", "net1", MEMBERS[1:]).signer()
    assert str(folder / name) in str(info.value) and "chmod 600" in str(info.value)


def test_check_private_refuses_a_folder(tmp_path):
    with pytest.raises(SecurityError, match="not a regular file"):
        check_private(tmp_path)


def test_peer_with_a_readable_key_exits_2_in_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    folder = _keys(tmp_path / "k")
    os.chmod(folder / "s1.key", 0o644)
    assert main(["peer", "s1", "--network", "net1", "--secure", str(folder),
                 "--listen", "tls/127.0.0.1:0", "--out", "o"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "s1.key" in line and "chmod 600" in line


def test_keys_refuses_to_reuse_a_readable_ca_or_member_key(tmp_path, capsys):
    folder = _keys(tmp_path / "k")
    os.chmod(folder / "ca.key", 0o644)
    assert main(["keys", "net1", "--out", str(folder), "--members", "s4"]) == 2
    assert "ca.key" in _one_line(capsys.readouterr().err)
    assert not (folder / "s4.key").exists()
    os.chmod(folder / "ca.key", 0o600)
    os.chmod(folder / "s1.key", 0o644)
    assert main(["keys", "net1", "--out", str(folder), "--members", "s1"]) == 2
    assert "s1.key" in _one_line(capsys.readouterr().err)


def test_run_secure_with_a_readable_key_starts_nothing(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    folder = _keys(tmp_path / "k")
    os.chmod(folder / "world.ed25519", 0o644)
    assert main(["run", "--secure", str(folder), "--set", "scenario.num_scans=3",
                 "--out", "out"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "world.ed25519" in line and "chmod 600" in line
    assert not (tmp_path / "out").exists()  # the run folder it made is gone, nothing started
