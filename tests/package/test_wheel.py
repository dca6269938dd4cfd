"""The wheel carries what a user needs (the shipped models and examples) and works when
installed from the built file into a fresh virtual environment."""

import os
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


CLEAN = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
"""The environment without a path that would import the source tree instead of the wheel."""


def run(*args, cwd=None) -> str:
    done = subprocess.run(args, capture_output=True, text=True, cwd=cwd, timeout=900, env=CLEAN)
    assert done.returncode == 0, f"{' '.join(map(str, args))}\n{done.stdout}\n{done.stderr}"
    return done.stdout


@pytest.mark.slow
def test_the_wheel_installs_and_runs_in_a_fresh_environment(tmp_path):
    run(sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", tmp_path, ROOT)
    (wheel,) = tmp_path.glob("hptrack-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for shipped in (
        "hptrack/examples/plan_once.py",
        "hptrack/examples/paper-flight.yaml",
        "hptrack/examples/stonesoup_tracking.py",
        "hptrack/learning/models/adfq-n2.pt",
    ):
        assert shipped in names
    assert not any(n.startswith(("tests/", "benchmarks/", "docs/")) for n in names)

    env = tmp_path / "venv"
    venv.create(env, with_pip=True)
    python = env / "bin" / "python"
    run(python, "-m", "pip", "install", "--quiet", wheel)
    where = "import hptrack; print(hptrack.__version__, hptrack.__file__)"
    version, location = run(python, "-c", where).split()
    assert Path(location).is_relative_to(env)
    assert f"hptrack-{version}-" in wheel.name
    hptrack = env / "bin" / "hptrack"
    assert "plan_once.py" in run(hptrack, "examples")
    run(hptrack, "examples", "--to", tmp_path / "ex")
    out = run(
        python, "run_episode.py", "--planner", "stationary", "--targets", "1", cwd=tmp_path / "ex"
    )
    assert out.splitlines()[-1].startswith("U = ")
