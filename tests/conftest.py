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
