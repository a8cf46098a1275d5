"""atomic_write_*: content replaced in one step, no temporary files left behind."""

from __future__ import annotations

import os
import stat

import pytest

from phyagentos.protocol import atomic_write_bytes, atomic_write_text


def test_atomic_write_text_replaces_content_and_leaves_no_temp_files(tmp_path):
    target = tmp_path / "doc.md"
    target.write_text("old content\n", encoding="utf-8")

    atomic_write_text(target, "new content ✓\n")

    assert target.read_text(encoding="utf-8") == "new content ✓\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["doc.md"]


def test_atomic_write_bytes_creates_missing_file(tmp_path):
    target = tmp_path / "blob.bin"

    atomic_write_bytes(target, b"\x00\x01\xff")

    assert target.read_bytes() == b"\x00\x01\xff"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blob.bin"]


def test_atomic_write_text_does_not_translate_newlines(tmp_path):
    target = tmp_path / "crlf.md"
    text = "a\r\nb\nc\r"

    atomic_write_text(target, text)

    assert target.read_bytes() == text.encode("utf-8")


def test_failed_write_removes_temp_file_and_keeps_original(tmp_path):
    target = tmp_path / "doc.md"
    target.write_bytes(b"original")

    with pytest.raises(TypeError):
        atomic_write_bytes(target, "not bytes")  # type: ignore[arg-type]

    assert target.read_bytes() == b"original"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["doc.md"]


def test_unencodable_text_raises_and_keeps_original(tmp_path):
    target = tmp_path / "doc.md"
    target.write_bytes(b"original")

    with pytest.raises(UnicodeEncodeError):
        atomic_write_text(target, "lone surrogate \ud800")

    assert target.read_bytes() == b"original"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["doc.md"]


def test_write_into_missing_directory_raises_oserror(tmp_path):
    with pytest.raises(OSError):
        atomic_write_text(tmp_path / "missing" / "doc.md", "x")
    assert not (tmp_path / "missing").exists()


def test_atomic_write_keeps_permission_bits_of_existing_file(tmp_path):
    target = tmp_path / "doc.md"
    target.write_text("old", encoding="utf-8")
    os.chmod(target, 0o640)

    atomic_write_text(target, "new")

    assert stat.S_IMODE(target.stat().st_mode) == 0o640


def test_new_file_gets_umask_permissions_not_tempfile_0600(tmp_path):
    target = tmp_path / "doc.md"
    umask = os.umask(0)
    os.umask(umask)

    atomic_write_text(target, "x")

    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask


def test_repeated_writes_leave_only_the_target(tmp_path):
    target = tmp_path / "doc.md"
    for i in range(20):
        atomic_write_text(target, f"version {i}\n")
    assert target.read_text(encoding="utf-8") == "version 19\n"
    assert [p.name for p in tmp_path.iterdir()] == ["doc.md"]
