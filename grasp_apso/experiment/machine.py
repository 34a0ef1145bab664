"""The machine a measurement ran on: Python and numpy versions, CPU, load average and the
git commit of the sources."""

from __future__ import annotations

import os
import platform
import subprocess
from typing import Any

import numpy as np


def _machine() -> dict[str, Any]:
    info: dict[str, Any] = {"python": platform.python_version(), "numpy": np.__version__,
                            "cpus": os.cpu_count(), "platform": platform.platform()}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    info["cpu"] = line.split(":", 1)[1].strip()
                    break
        info["load_average_at_start"] = list(os.getloadavg())
    except OSError:
        pass
    # The commit of the sources (GRASP_APSO_GIT_COMMIT names it for a copy outside git) and
    # whether the planner's sources (the grasp_apso package) differ from it.
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    info["git_commit"] = os.environ.get("GRASP_APSO_GIT_COMMIT")
    if not info["git_commit"]:
        try:
            git = ["git", "-C", here]
            info["git_commit"] = subprocess.run(git + ["rev-parse", "--short", "HEAD"], capture_output=True,
                                                text=True, timeout=5).stdout.strip() or None
            changed = subprocess.run(git + ["status", "--porcelain", "--", "."], capture_output=True, text=True,
                                     timeout=5).stdout.split("\n")
            info["uncommitted_sources"] = sorted(line[3:] for line in changed if line.strip())
        except Exception:
            info["git_commit"] = None
    return info
