"""The README's first-use examples run as printed: the "Python API" example, and the sample
output of ``grasp_apso_plan --object cube --algorithm both --seed 0``, which must match what
the command prints now (every line shown, times aside).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from readme_blocks import readme_example, run_readme_example

REPO = Path(__file__).resolve().parents[1]


def test_python_api_example_runs(monkeypatch, capsys):
    monkeypatch.chdir(REPO)  # the example loads grasp_apso/data/meshes/apple.stl
    ns = run_readme_example("python-api")
    result, scene, pose = ns["result"], ns["scene"], ns["pose"]
    cands = result.candidates
    assert 1 <= len(cands) <= 3
    assert [c.rank for c in cands] == list(range(len(cands)))  # 0 = best
    assert [c.grasp_quality for c in cands] == sorted((c.grasp_quality for c in cands), reverse=True)
    assert all(c.sim_result in (0, 1) for c in cands)  # simulate=True ran for each
    # The table is under the apple placed at pose (z of its lowest point); no hand below it.
    lowest = float((ns["apple"].mesh.vertices @ pose[:3, :3].T + pose[:3, 3])[:, 2].min())
    assert np.allclose(scene.planes, [[0.0, 0.0, 1.0, -lowest]])
    assert all(c.scene_distance >= ns["options"].clearance - 1e-6 for c in cands)
    # The standalone simulation agrees with the one the plan ran on the best grasp.
    assert ns["check"].held == (cands[0].sim_result == 1)
    assert ns["grasp_q"].shape == (18,) and ns["start"].shape == (4, 4)
    out = capsys.readouterr().out
    assert out.count("rank ") == len(cands) and "rank 0:" in out


def _masked(line: str) -> str:
    """Times vary from run to run: their numbers are masked."""
    return re.sub(r"\d+\.\d+", "#", line) if "time" in line else line


def test_cli_sample_output_is_current(tmp_path):
    block = readme_example("cli-output").splitlines()
    command = block[0]
    assert command.startswith("$ grasp_apso_plan ")
    argv = command.split()[2:]
    run = subprocess.run([sys.executable, "-m", "grasp_apso.tools.cli", *argv], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    actual = [_masked(line.rstrip()) for line in run.stdout.splitlines()]
    # Every line the README shows appears, in the same order ("..." = lines left out).
    position = 0
    for line in block[1:]:
        if line.strip() == "...":
            continue
        want = _masked(line.rstrip())
        try:
            position = actual.index(want, position) + 1
        except ValueError:
            raise AssertionError(f"README line not in the output (in this order): {line!r}\n"
                                 f"output:\n{run.stdout}") from None
    assert "APSO" in run.stdout and (tmp_path / "grasp_apso_out" / "cube_convergence.png").is_file()
