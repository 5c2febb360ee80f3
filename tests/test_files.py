"""Atomic writes (scpformer.files.write_bytes_atomic): links are written through, and a path
that is not a regular file is never replaced."""

import os

import pytest

from scpformer.files import write_bytes_atomic


def test_a_symbolic_link_is_written_through_and_kept(tmp_path):
    target = tmp_path / "target.npz"
    target.write_bytes(b"old")
    link = tmp_path / "link.npz"
    link.symlink_to(target)
    write_bytes_atomic(link, b"new")
    assert link.is_symlink() and target.read_bytes() == b"new"


def test_a_pipe_is_refused_and_left_in_place(tmp_path):
    fifo = tmp_path / "fifo.npz"
    os.mkfifo(fifo)
    with pytest.raises(FileExistsError, match="not a regular file"):
        write_bytes_atomic(fifo, b"data")
    assert fifo.exists() and not fifo.is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo.npz"]  # no temporary left
