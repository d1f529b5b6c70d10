"""Atomic writes and corrupt-artefact detection."""
import os

import numpy as np
import pytest
import torch

from drfkit.util.io import (CorruptArtefactError, atomic_save_npz, atomic_torch_save, atomic_write_text,
                       cached_npz, load_npz_checked, param_hash, torch_load_checked)


def test_atomic_write_leaves_no_temp_files_and_replaces(tmp_path):
    path = tmp_path / "sub" / "a.txt"
    atomic_write_text(path, "one")
    atomic_write_text(path, "two")
    assert path.read_text() == "two"
    assert os.listdir(path.parent) == ["a.txt"]


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "a.txt"
    atomic_write_text(path, "good")

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        atomic_write_text(path, "half")
    assert path.read_text() == "good" and os.listdir(tmp_path) == ["a.txt"]


def test_param_hash_ignores_key_order_and_sees_values():
    assert param_hash({"a": 1, "b": [1, 2]}) == param_hash({"b": [1, 2], "a": 1})
    assert param_hash({"a": 1}) != param_hash({"a": 2})


def test_cached_npz_builds_once_and_rebuilds_a_corrupt_file(tmp_path, capsys):
    calls = []

    def build():
        calls.append(1)
        return {"x": np.arange(5)}

    a = cached_npz(tmp_path, "thing", {"n": 5}, build)
    b = cached_npz(tmp_path, "thing", {"n": 5}, build)
    assert len(calls) == 1 and np.array_equal(a["x"], b["x"])
    (path,) = tmp_path.glob("thing-*.npz")
    path.write_bytes(path.read_bytes()[:20])  # truncate, as a killed copy would
    with pytest.raises(CorruptArtefactError, match=str(path.name)):
        load_npz_checked(path)
    c = cached_npz(tmp_path, "thing", {"n": 5}, build)
    assert len(calls) == 2 and np.array_equal(c["x"], np.arange(5))
    assert "rebuilding" in capsys.readouterr().err


def test_corrupt_checkpoint_gives_one_clear_error(tmp_path):
    path = tmp_path / "m.pt"
    atomic_torch_save(path, {"w": torch.ones(100)})
    assert torch.equal(torch_load_checked(path)["w"], torch.ones(100))
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    with pytest.raises(CorruptArtefactError) as err:
        torch_load_checked(path)
    assert "m.pt" in str(err.value) and "delete it" in str(err.value)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        torch_load_checked(tmp_path / "missing.pt")


def test_atomic_npz_roundtrip(tmp_path):
    atomic_save_npz(tmp_path / "a.npz", x=np.ones((2, 3), np.float32))
    assert load_npz_checked(tmp_path / "a.npz")["x"].shape == (2, 3)


def test_written_files_are_readable_by_others(tmp_path):
    path = atomic_write_text(tmp_path / "r.txt", "x")
    assert path.stat().st_mode & 0o044  # not the 0600 of a bare mkstemp
