"""What the experiment runs (seeds, objects, swarm size, snapshot iterations, speed sweeps)
and the names used throughout: output folder, labels and colours of the approaches, the
penetration limit of a valid grasp and the pyswarms settings."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any


from ..model import builtin as builtin_objects
DEFAULT_OUT = os.path.join("docs", "experiment")
OBJECT_LABELS = {
    "sphere": "sphere (diameter 5 cm)",
    "cube": "cube (edge 7 cm)",
    "barrel": "barrel (11 x 3 cm)",
    "fish": "fish (29 x 6 x 7 cm)",
}
#: Keys of the approaches in ``results.json`` and their labels in the report.
ALGORITHM_LABELS = {
    "pso": "simple PSO",
    "apso": "APSO",
    "pso_equal_budget": "PSO, APSO's budget",
    "pyswarms_global": "pyswarms GlobalBestPSO",
    "pyswarms_local": "pyswarms LocalBestPSO",
}
_COLORS = {
    "apso": "#0072B2",
    "pso": "#D55E00",
    "pso_equal_budget": "#E69F00",
    "pyswarms_global": "#009E73",
    "pyswarms_local": "#CC79A7",
}
PENETRATION_LIMIT = 0.001  #: m, python-fcl check of the valid-grasp definition
#: pyswarms settings: our PSO's coefficients, positions clamped into the bounds like ours.
PYSWARMS_OPTIONS = {"c1": 1.0, "c2": 1.5, "w": 0.6}
PYSWARMS_LOCAL = {"k": 5, "p": 2}
PYSWARMS_BOUNDARY = "nearest"


@dataclass(frozen=True)
class SpeedConfig:
    """What the speed measurements sweep (see :func:`run_speed`)."""

    sweep_object: str = "sphere"
    particles: tuple[int, ...] = (15, 30, 60, 120)
    iterations: tuple[int, ...] = (10, 25, 50, 100)
    repeats: int = 5  #: runs (seeds 0..repeats-1) per point, median reported
    #: (label, kind, size): "icosphere" size = subdivisions, "uv" size = rings = segments.
    meshes: tuple[tuple[str, str, int], ...] = (
        ("icosphere s=3", "icosphere", 3),
        ("icosphere s=4", "icosphere", 4),
        ("uv-sphere 49x49", "uv", 49),
        ("icosphere s=5", "icosphere", 5),
        ("icosphere s=6", "icosphere", 6),
    )
    mesh_repeats: int = 3  #: plans per mesh: the first cold (caches cleared), the rest warm
    per_object_runs: int = 5  #: plans per built-in object and algorithm (bench script)

    @classmethod
    def quick(cls) -> "SpeedConfig":
        return cls(particles=(15, 30), iterations=(5, 10), repeats=1,
                   meshes=(("icosphere s=2", "icosphere", 2), ("icosphere s=3", "icosphere", 3)),
                   mesh_repeats=2, per_object_runs=1)


@dataclass(frozen=True)
class Part2Config:
    """The executable-grasp scenarios (fewer seeds than Table 3: each plan does more).

    ``table``: each object resting on a table (a support plane under its lowest point)
    against free space, one grasp per plan; ``candidates``: ``max_grasps`` ranked candidates
    on the table against one grasp; ``simulation``: the MuJoCo check of the best grasp of
    APSO, the simple PSO and the pyswarms peers in free space (when
    :mod:`grasp_apso.simulation` and mujoco can be imported).
    """

    seeds: int = 5
    max_grasps: int = 5
    table: bool = True
    candidates: bool = True
    simulation: bool = True

    @classmethod
    def quick(cls) -> "Part2Config":
        return cls(seeds=1, max_grasps=3)


@dataclass(frozen=True)
class ExperimentConfig:
    seeds: int = 20
    objects: tuple[str, ...] = builtin_objects.BUILTIN_OBJECTS
    particles: int = 60
    iterations: int = 50
    snapshots: tuple[int, ...] = (5, 20, 50)
    equal_budget: bool = True
    peers: bool = True
    speed: SpeedConfig | None = field(default_factory=SpeedConfig)
    part2: Part2Config | None = field(default_factory=Part2Config)
    quick: bool = False
    dpi: int = 100
    command: str = "python -m grasp_apso.experiment"

    @classmethod
    def quick_config(cls, **kw: Any) -> "ExperimentConfig":
        base = dict(seeds=2, objects=("sphere", "cube"), particles=20, iterations=10, snapshots=(2, 5, 10),
                    speed=SpeedConfig.quick(), part2=Part2Config.quick(), quick=True, dpi=70)
        base.update(kw)
        return cls(**base)

    def __post_init__(self) -> None:
        if self.seeds < 1:
            raise ValueError(f"seeds: expected >= 1, got {self.seeds}")
        unknown = [o for o in self.objects if o not in builtin_objects.BUILTIN_OBJECTS]
        if unknown or not self.objects:
            raise ValueError(f"objects: expected some of {builtin_objects.BUILTIN_OBJECTS}, got {self.objects}")
        if len(self.snapshots) != 3 or not all(1 <= k <= self.iterations for k in self.snapshots):
            raise ValueError(f"snapshots: expected 3 iterations within 1..{self.iterations}, got {self.snapshots}")
