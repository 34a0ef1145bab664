"""The paper's experiment (section 5, Table 3), peer optimisers and planner speed.

Run ``python -m grasp_apso.experiment`` (or ``make experiment``) from the repository root.
It plans with APSO and the simple PSO on the four built-in objects (np = 60, nit = 50)
over fixed seeds 0..N-1 and writes, into ``--out`` (default ``docs/experiment/``):

- ``report.md``: Table 3 in numbers (global best at iterations 5, 20 and 50: median and
  inter-quartile range of the fitness; for the final grasp the contact count, epsilon,
  force-closure and valid rates, plan time and evaluations), the paper's claims checked
  with the numbers, PSO given APSO's evaluation budget, pyswarms' global- and local-best
  PSO on the same fitness and budget, and the planner's speed;
- ``results.json``: every number of the report and every run (per-iteration history);
- pictures: ``table3_<object>.png`` (best grasp at iterations 5, 20, 50, rows PSO and
  APSO, like the paper's Table 3), ``convergence.png`` (median best fitness per
  iteration with the inter-quartile band), ``convergence_evaluations.png`` (the same
  against evaluations, with the equal-budget PSO and pyswarms) and ``speed.png``;
- the executable-grasp sections (DESIGN.md Part 2; fewer seeds, ``Part2Config``): the
  objects resting on a table against free space, ranked candidates (quality by rank,
  distinctness, time against one grasp) and the MuJoCo held rate of APSO, PSO and the
  peers with the protocol written out (when :mod:`grasp_apso.simulation` imports).

The Table 3 runs plan one grasp each (``max_grasps=1``, the paper's setting).

Definitions used throughout:

- *valid* grasp: at least 3 fingertip contacts, no penetration beyond 1 mm by the
  python-fcl check, joint limits respected: ``n_contacts >= 3 and result.valid and
  result.fcl.legal`` plus an explicit check of ``joint_positions`` against the hand's
  limits;
- *evaluation*: one particle decoded (GRG candidates included), as counted by the planner;
- the global best at iteration k of a run is ``history[k - 1].best_fitness``; the grasp
  drawn for it comes from re-running the same seed with ``iterations=k``: a run's first k
  iterations do not depend on the iteration count, which the experiment verifies for
  every re-run (``determinism`` in the JSON).

pyswarms uses numpy's global random state: it is seeded with ``np.random.seed(seed)``
before each of its runs (their API).

The package, one concern per module:

- ``config``: what the experiment runs (:class:`ExperimentConfig`, :class:`SpeedConfig`),
  labels, colours and the pyswarms settings;
- ``runs``: APSO, PSO, PSO on APSO's budget and pyswarms over the seeds;
- ``records`` and ``stats``: one plan as a record (the valid-grasp definition), statistics
  over seeds;
- ``analysis``: the summary per object and approach, the claims, the anomalies;
- ``speed``: the speed measurements (also run by ``bench/bench_planner.py``);
- ``part2`` and ``report_part2``: the table, candidates and simulation runs and their sections;
- ``figures``: the pictures (Table 3 grids, convergence, speed);
- ``report``, ``results_json``, ``machine``: ``report.md``, ``results.json`` and the
  machine description;
- ``pipeline``: :func:`run_experiment`, everything in order; ``cli``: :func:`main`.
"""

from .analysis import evaluate_claims, find_anomalies, summarise
from .cli import build_parser, main
from .config import (
    ALGORITHM_LABELS,
    DEFAULT_OUT,
    OBJECT_LABELS,
    PENETRATION_LIMIT,
    PYSWARMS_BOUNDARY,
    PYSWARMS_LOCAL,
    PYSWARMS_OPTIONS,
    ExperimentConfig,
    Part2Config,
    SpeedConfig,
)
from .figures import plot_convergence_panels, plot_evaluation_panels, plot_speed, table3_figures
from .machine import _machine  # noqa: F401  (bench/bench_planner.py)
from .pipeline import run_experiment
from .records import record_of, valid_grasp
from .report import format_speed_tables, headline_table, write_report
from .results_json import _compact_json  # noqa: F401  (bench/bench_planner.py)
from .runs import pyswarms_status, run_main, run_pyswarms
from .speed import run_speed

__all__ = [
    "ALGORITHM_LABELS",
    "ExperimentConfig",
    "SpeedConfig",
    "main",
    "run_experiment",
    "run_speed",
    "format_speed_tables",
    "plot_speed",
    "valid_grasp",
]
