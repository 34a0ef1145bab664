"""The planner's speed: plan time per object, and how it grows with particles, iterations
and mesh triangles (also run alone by ``bench/bench_planner.py``)."""

from __future__ import annotations

import time
from dataclasses import asdict
from typing import Any, Callable, Sequence

import numpy as np

from ..model import objects
from ..model import builtin as builtin_objects
from ..model.hand import load_hand
from ..search.planner import PlanOptions, plan
from .config import SpeedConfig
from .progress import _log
from .stats import _stats


def _sweep_mesh(kind: str, size: int):
    import trimesh

    if kind == "icosphere":
        return trimesh.creation.icosphere(subdivisions=size, radius=0.025)
    if kind == "uv":
        return trimesh.creation.uv_sphere(radius=0.025, count=[size, size])
    raise ValueError(f"mesh kind: {kind!r}")


def _clear_caches() -> None:
    from ..cache import clear_caches

    clear_caches("sdf_grid", "mesh_bvh")


def run_speed(speed: SpeedConfig, hand=None, per_object: dict | None = None,
              objects_: Sequence[str] = builtin_objects.BUILTIN_OBJECTS, log: Callable[[str], None] = _log) -> dict[str, Any]:
    """Plan time per object, and how it grows with particles, iterations and triangles.

    ``per_object``: plan times already measured (``{object: {algorithm: [records]}}``);
    otherwise ``speed.per_object_runs`` plans per object and algorithm are timed here.
    Mesh sweep: spheres of 5 cm diameter; per mesh the object construction (validation),
    the preparation (signed-distance grid; caches cleared first), a cold plan (includes the
    python-fcl BVH build) and warm plans are timed separately (APSO, np = 60, nit = 50).
    """
    hand = hand or load_hand()
    result: dict[str, Any] = {"config": asdict(speed), "per_object": {}, "particles": [], "iterations": [],
                              "meshes": []}

    def timed(obj, options, seed):
        r = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hand)
        return r

    for name in objects_:
        obj = builtin_objects.builtin(name)
        result["per_object"][name] = {}
        for alg in ("apso", "pso"):
            if per_object is not None:
                recs = per_object[name][alg]
                times = [r["planning_time"] for r in recs]
                evals = [r["evaluations"] for r in recs]
            else:
                timed(obj, PlanOptions(iterations=1, max_grasps=1), 0)  # preparation outside the timing
                rs = [timed(obj, PlanOptions(algorithm=alg, max_grasps=1), s) for s in range(speed.per_object_runs)]
                times = [r.planning_time for r in rs]
                evals = [r.evaluations for r in rs]
            result["per_object"][name][alg] = {
                "runs": len(times), "planning_time": _stats(times), "evaluations": _stats(evals),
                "evaluations_per_second": _stats([e / t for e, t in zip(evals, times) if t > 0]),
            }
        log(f"speed {name}: APSO {result['per_object'][name]['apso']['planning_time']['median']:.3f} s, "
            f"PSO {result['per_object'][name]['pso']['planning_time']['median']:.3f} s (median)")

    obj = builtin_objects.builtin(speed.sweep_object)
    timed(obj, PlanOptions(iterations=1, max_grasps=1), 0)
    for key, values in (("particles", speed.particles), ("iterations", speed.iterations)):
        for v in values:
            for alg in ("apso", "pso"):
                options = PlanOptions(algorithm=alg, max_grasps=1, **{key: int(v)})
                rs = [timed(obj, options, s) for s in range(speed.repeats)]
                times = [r.planning_time for r in rs]
                evals = [r.evaluations for r in rs]
                result[key].append({
                    key: int(v), "algorithm": alg, "planning_time": _stats(times),
                    "evaluations": _stats(evals),
                    "evaluations_per_second": _stats([e / t for e, t in zip(evals, times) if t > 0]),
                })
        log(f"speed sweep over {key} done")

    for label, kind, size in speed.meshes:
        mesh = _sweep_mesh(kind, size)
        t0 = time.perf_counter()
        obj = objects.from_arrays(np.asarray(mesh.vertices), np.asarray(mesh.faces), name=f"{kind}{size}")
        construct = time.perf_counter() - t0
        _clear_caches()
        rs = [timed(obj, PlanOptions(max_grasps=1), s) for s in range(max(1, speed.mesh_repeats))]
        warm = [r.planning_time for r in rs[1:]] or [rs[0].planning_time]
        entry = {
            "label": label, "triangles": int(len(obj.mesh.faces)), "vertices": int(len(obj.mesh.vertices)),
            "hull_vertices": int(len(obj.hull_vertices)), "closed": bool(obj.mesh.is_watertight),
            "construction_time": construct, "preparation_time": rs[0].preparation_time,
            "plan_time_cold": rs[0].planning_time, "plan_time_warm": _stats(warm)["median"],
            "total_cold": construct + rs[0].preparation_time + rs[0].planning_time,
            "prep_plus_plan": rs[0].preparation_time + rs[0].planning_time,
            "evaluations": _stats([r.evaluations for r in rs])["median"],
            "fitness": _stats([r.fitness for r in rs])["median"],
        }
        result["meshes"].append(entry)
        log(f"speed mesh {label} ({entry['triangles']} triangles): prep {entry['preparation_time']:.2f} s, "
            f"plan cold {entry['plan_time_cold']:.2f} s, warm {entry['plan_time_warm']:.2f} s")
    _clear_caches()
    return result
