"""A full disk: a write that fails with ENOSPC (here: at fsync, where a full disk shows on many
file systems) leaves the previous file intact, no temporary file behind, and stops with one clear
error naming the path. Covers the writers of checkpoints, tables, figures and caches."""
import errno
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402

import drfkit.util.io as dio  # noqa: E402


def _full(fd):
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.mark.parametrize("kind", ["checkpoint", "table", "figure", "cache", "json"])
def test_enospc_keeps_the_previous_file_and_names_the_path(tmp_path, monkeypatch, kind):
    path = tmp_path / f"out.{kind}"
    path.write_bytes(b"previous version")
    fig = plt.figure() if kind == "figure" else None
    write = {"checkpoint": lambda: dio.atomic_torch_save(path, {"w": torch.ones(3)}),
             "table": lambda: dio.atomic_write_csv(path, pd.DataFrame({"a": [1.0]})),
             "figure": lambda: dio.atomic_savefig(path, fig),
             "cache": lambda: dio.atomic_save_npz(path, x=np.ones(3)),
             "json": lambda: dio.atomic_write_json(path, {"a": 1})}[kind]
    monkeypatch.setattr(dio.os, "fsync", _full)
    with pytest.raises(dio.DiskFullError, match=rf"no space left on the device while writing {path}.*intact"):
        write()
    assert path.read_bytes() == b"previous version"
    assert sorted(os.listdir(tmp_path)) == [path.name]  # no temporary file left
    if fig is not None:
        plt.close(fig)
