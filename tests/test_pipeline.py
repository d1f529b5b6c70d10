"""The papermill pipeline stops at the first failing notebook, names it, and keeps the
executed copy with the error; the manifest records the failure."""
import json
import subprocess
import sys

import pytest

from drfkit.study.params import load_profile, write_profile
from drfkit.util.paths import REPO_ROOT


@pytest.mark.slow
def test_pipeline_stops_at_first_failing_notebook_and_names_it(tmp_path):
    # valid parameters, but device 'cuda' where torch sees no GPU fails in the notebook's first cell;
    # CUDA_VISIBLE_DEVICES="" hides a GPU from the run, so the test runs on a CUDA machine too
    values = load_profile("quick") | {"profile": "failing", "device": "cuda"}
    path = tmp_path / "failing.yaml"
    write_profile(path, values)
    env = {"DRF_RESULTS": str(tmp_path / "results"), "PATH": "/usr/bin:/bin", "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run([sys.executable, "-m", "drfkit", "reproduce", "--profile", str(path),
                           "--only", "00_data_prep", "05_timing", "--workers", "2"],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert "FAILED: notebook 00_data_prep" in proc.stderr and "no GPU" in proc.stderr
    assert "== 05_timing" not in proc.stdout  # stopped at the first failure
    executed = tmp_path / "results" / "failing" / "executed"
    assert (executed / "00_data_prep.failed.ipynb").exists()
    assert not (executed / "00_data_prep.ipynb").exists() and not list(executed.glob(".*partial*"))
    manifest = json.loads((tmp_path / "results" / "failing" / "manifest.json").read_text())
    assert manifest["pipeline"]["status"] == "failed in 00_data_prep"
    assert manifest["pipeline"]["workers"] == "2"  # --workers reaches the environment the kernels inherit



def test_overrides_are_parsed_as_yaml_and_checked():
    from drfkit.study.params import ParameterError
    from drfkit.study.params import parse_overrides

    assert parse_overrides(["eval_studies=[pedestrians]", "threads=1"]) == {"eval_studies": ["pedestrians"],
                                                                            "threads": 1}
    assert parse_overrides(None) == {}
    for bad, fragment in (("eval_studies", "KEY=VALUE"), ("no_such_key=1", "unknown parameter"),
                          ("seeds=[1, 2", "not a YAML value")):
        with pytest.raises(ParameterError, match=fragment):
            parse_overrides([bad])


@pytest.mark.slow
@pytest.mark.parametrize("only,setting,named", [
    ("04_ood_noise_evaluation", "eval_studies=[nuscenes]", "eval_studies"),
    # pend_epochs belongs to notebook 01: a run of 00 alone still checks it, against the whole profile's schema
    ("00_data_prep", "pendulum.epochs=abc", "epochs"),
])
def test_overrides_reach_validation_before_any_notebook_runs(tmp_path, only, setting, named):
    env = {"DRF_RESULTS": str(tmp_path / "results"), "PATH": "/usr/bin:/bin", "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run([sys.executable, "-m", "drfkit", "reproduce", "--profile", "quick", "--only", only,
                           "--set", setting], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2 and named in proc.stderr, proc.stderr[-2000:]
    assert not (tmp_path / "results" / "quick" / "executed").exists()


def test_a_bad_worker_count_is_refused_before_any_notebook_runs(tmp_path, monkeypatch, capsys):
    from drfkit.cli import main as cli

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    with pytest.raises(SystemExit) as stop:
        cli(["reproduce", "--profile", "quick", "--only", "00_data_prep", "--workers", "two"])
    assert stop.value.code == 2 and "--workers" in capsys.readouterr().err
    assert not (tmp_path / "results" / "quick" / "executed").exists()


@pytest.mark.slow
def test_the_pipeline_s_kernels_run_over_ipc_and_print_no_tcp_warning(tmp_path, capfd):
    """drfkit.book.pipeline.ipc_kernels: the kernel papermill starts listens on Unix sockets in a
    private folder, not on TCP ports, so ipykernel has no 'running over TCP without encryption'
    warning to print into the terminal of `make reproduce`."""
    import os

    import nbformat
    import papermill as pm

    from drfkit.book.pipeline import ipc_kernels

    nb = nbformat.v4.new_notebook(metadata={"kernelspec": {"name": "python3", "display_name": "Python 3",
                                                           "language": "python"}})
    nb.cells = [nbformat.v4.new_code_cell(
        "import json, ipykernel.connect\n"
        "info = json.load(open(ipykernel.connect.get_connection_file()))\n"
        "print(info['transport'], info['ip'])")]
    nbformat.write(nb, tmp_path / "in.ipynb")
    with ipc_kernels() as config:
        folder = os.path.dirname(config.KernelManager.ip)
        assert oct(os.stat(folder).st_mode & 0o777) == "0o700"
        pm.execute_notebook(str(tmp_path / "in.ipynb"), str(tmp_path / "out.ipynb"), progress_bar=False,
                            kernel_name="python3", cwd=str(tmp_path), config=config)
    transport, ip = nbformat.read(tmp_path / "out.ipynb", as_version=4).cells[0].outputs[0]["text"].split()
    assert transport == "ipc" and ip == config.KernelManager.ip
    assert not os.path.exists(folder)  # the sockets' folder is gone with the run
    assert "without encryption" not in capfd.readouterr().err
