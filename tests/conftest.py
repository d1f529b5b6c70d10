"""Shared fixtures."""
import pytest
import torch


@pytest.fixture
def one_thread():
    """One torch thread for the test (training results depend on the thread count), restored after."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture
def load_tool():
    """``load_tool("slow_cells")``: the script tools/slow_cells.py as a module (tools/ holds scripts,
    not a package, so it is loaded from its file)."""
    import importlib.util

    from drfkit.util.paths import REPO_ROOT

    def load(name: str):
        spec = importlib.util.spec_from_file_location(name, REPO_ROOT / "tools" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load


@pytest.fixture
def dynamics_profile(tmp_path, monkeypatch):
    """``dynamics_profile("quick")``: notebook 02's parameters of a profile (what the ablation and the regime map
    read: the data seed, the device); with ``tmp=True`` its results (and data cache) under ``tmp_path``."""
    from drfkit.study.params import for_notebook, load_profile

    def make(profile: str = "quick", tmp: bool = True):
        if tmp:
            monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
        return for_notebook("02_pendulum_dynamics", load_profile(profile))

    return make
