#!/usr/bin/env python3
"""Which of DexGraspBench's parameters drops a grasp that our check holds: one at a time.

Rerunnable diagnostic, not a test::

    .venv/bin/python bench/dgb_factors.py --hand FILE --cases sphere:2 cup:0
    .venv/bin/python bench/dgb_factors.py --hand FILE --from-json bench/results/held_rate_FILE.json
    .venv/bin/python bench/dgb_factors.py --hand FILE --cases banana:0 --pregrasp-fractions 0.5 0.2
    .venv/bin/python bench/dgb_factors.py --hand dclaw --cases sphere:0 cube:1 --no-groups --squeeze-scales 0.5

``bench/held_rate.py --dexgraspbench`` checks every candidate with our simulation parameters
and with DexGraspBench's (:data:`held_rate.DEXGRASPBENCH`); where the two verdicts differ
this says why. Each case (``object:seed``, the object resting on a table, as ``held_rate.py``
plans it: APSO with the planner's defaults, or with ``--from-json`` the run's algorithm,
swarm and ``simulate``) is planned once and its best grasp replayed with:

- ``ours`` and ``dgb`` (all of DexGraspBench's parameters);
- ``dgb - G``: DexGraspBench's parameters with the group G set back to ours;
- ``ours + G``: ours with only the group G taken from DexGraspBench;

the groups being the servo gain, the torsional friction, the contact softness (solref), the
contact impedance (solimp), the closing and squeeze ramp times and the settling before the
disturbance. ``--pregrasp-fractions`` adds DexGraspBench's parameters with the fingers
starting that fraction of the way from the grasp posture back to the reply's pre-grasp;
``--squeeze-scales`` adds them, and ours, with the reply's squeeze offset scaled;
``--no-groups`` leaves out the one-group-at-a-time replays. A group whose ``dgb - G`` holds
where ``dgb`` drops is the one that decides.

``--from-json`` takes the cases from a ``held_rate.py --dexgraspbench`` run of the same
hand: the plans whose best grasp dropped with DexGraspBench's parameters (``--all-cases``:
every plan, to see what a change costs where it held). Prints a Markdown table (``H`` held,
``.`` dropped, then the largest shift in mm) with each variant's total; writes JSON
(``--out``, default ``bench/results/dgb_factors_<hand>.json``).

Measured with it: docs/any-hand-measurements.md, "The stop of 2026-12-06, ninth".
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from held_rate import BUILTINS, DEXGRASPBENCH, hand_path, mesh_names  # noqa: E402  (bench/, the script's folder)
from tables import markdown_table  # noqa: E402

#: DexGraspBench's parameters (:data:`held_rate.DEXGRASPBENCH`) by what they set.
GROUPS = {"servo gain": ("kp",), "torsional friction": ("torsional_friction",), "solref": ("solref",),
          "solimp": ("solimp",), "ramp times": ("hand_close_time", "hand_squeeze_time"),
          "settling": ("settle_time", "max_settle_time")}


def variants(pregrasp_fractions=(), squeeze_scales=(), groups: bool = True) -> list[tuple[str, dict, float]]:
    """The replays: (label, settings overrides of ours, squeeze scale); without ``groups``
    only ``ours``, ``dgb`` and the pre-grasp and squeeze variants."""
    dgb = dict(DEXGRASPBENCH)
    out = [("ours", {}, 1.0), ("dgb", dgb, 1.0)]
    if groups:
        out += [(f"dgb - {g}", {k: v for k, v in dgb.items() if k not in keys}, 1.0) for g, keys in GROUPS.items()]
        out += [(f"ours + {g}", {k: dgb[k] for k in keys}, 1.0) for g, keys in GROUPS.items()]
    out += [(f"dgb, pre-grasp x{f:g}", dgb | {"pregrasp_fraction": float(f)}, 1.0) for f in pregrasp_fractions]
    out += [(f"dgb, squeeze x{s:g}", dgb, float(s)) for s in squeeze_scales]
    out += [(f"ours, squeeze x{s:g}", {}, float(s)) for s in squeeze_scales]
    return out


def replay_case(task: tuple) -> dict:
    """Plan one case as ``held_rate.py`` does and replay its best grasp under every variant."""
    import numpy as np

    from held_rate import general_hand, load

    from grasp_apso.model.scene import Scene
    from grasp_apso.search.options import PlanOptions
    from grasp_apso.search.planner import plan
    from grasp_apso.simulation.any_hand import simulate_any_hand
    from grasp_apso.simulation.settings import SimulationSettings

    spec, name, seed, algorithm, plan_fields, runs = task
    hand, obj, pose = general_hand(spec), load(name), np.eye(4)
    scene = Scene.table_under(np.asarray(obj.mesh.vertices))
    options = PlanOptions(algorithm=algorithm, **plan_fields)
    row = {"object": name, "seed": seed, "algorithm": algorithm, "results": {}}
    result = plan(obj, pose, options, np.random.default_rng(seed), hand=hand, scene=scene)
    if not result.candidates:
        row["error"] = "no grasp"
        return row
    cand = result.candidates[0]
    q, squeeze = np.asarray(cand.joint_positions), np.asarray(cand.squeeze_positions)
    for label, overrides, scale in runs:
        try:
            sim = simulate_any_hand(hand, obj, pose, cand.wrist_pose, cand.pre_grasp_positions, q,
                                    q + scale * (squeeze - q), scene, options.friction,
                                    settings=replace(SimulationSettings(), **overrides))
            row["results"][label] = {"held": bool(sim.held), "shift_mm": round(1000 * float(sim.max_shift), 1)}
        except Exception as exc:  # recorded: a diagnostic reports, it does not stop
            row["results"][label] = {"held": False, "shift_mm": float("nan"), "error": f"{type(exc).__name__}: {exc}"}
    return row


def cases_from_json(path: Path, all_cases: bool) -> tuple[list[tuple[str, int, str]], dict]:
    """The (object, seed, algorithm) of a ``held_rate.py --dexgraspbench`` run's plans whose
    best grasp dropped with DexGraspBench's parameters (every plan with a grasp:
    ``all_cases``), and the run's planner options besides the algorithm (its swarm,
    ``simulate``), so that each case is planned again as that run planned it. Only the
    objects in their files' frames (the first of the run's poses, the identity)."""
    saved = json.loads(path.read_text())
    if saved.get("benchmark") != "held_rate" or not saved.get("dexgraspbench"):
        raise SystemExit(f"--from-json: {path} is not a held_rate.py --dexgraspbench run")
    if saved.get("stable"):
        raise SystemExit(f"--from-json: {path} planned the meshes in their resting poses (--stable); "
                         "this replays them in their files' frames")
    swarm = saved.get("swarm")
    fields = {"simulate": bool(saved.get("simulate"))} | (swarm if isinstance(swarm, dict) else {})
    cases = [(r["object"], int(r["seed"]), r.get("algorithm", "apso")) for r in saved["runs"]
             if r.get("pose", 0) == 0 and r.get("candidates")
             and (all_cases or not r["candidates"][0].get("dgb_held", True))]
    return cases, fields


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hand", required=True, help="as held_rate.py: a test hand's name or a URDF / MJCF file")
    parser.add_argument("--cases", nargs="+", default=[], metavar="OBJECT:SEED")
    parser.add_argument("--from-json", type=Path, help="a held_rate.py --dexgraspbench run of this hand")
    parser.add_argument("--all-cases", action="store_true", help="with --from-json: every plan, not only drops")
    parser.add_argument("--pregrasp-fractions", nargs="*", type=float, default=[])
    parser.add_argument("--squeeze-scales", nargs="*", type=float, default=[])
    parser.add_argument("--no-groups", action="store_true",
                        help="replay only ours, dgb and the --pregrasp-fractions / --squeeze-scales variants")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.hand in ("paper", ""):
        raise SystemExit("--hand: a general hand (the paper hand keeps its published check)")
    hand_path(args.hand)  # a bad name fails here, before any worker starts
    cases = []
    for text in args.cases:
        name, _, seed = text.partition(":")
        if not name or not seed.isdigit():
            raise SystemExit(f"--cases: expected OBJECT:SEED, got {text!r}")
        cases.append((name, int(seed), "apso"))
    plan_fields: dict = {}
    if args.from_json:
        saved_cases, plan_fields = cases_from_json(args.from_json, args.all_cases)
        cases += saved_cases
    if not cases:
        raise SystemExit("no cases: give --cases or --from-json")
    unknown = sorted({name for name, _, _ in cases} - set(BUILTINS) - set(mesh_names()))
    if unknown:
        raise SystemExit(f"--cases: unknown objects {unknown} (the built-ins and grasp_apso/data/meshes)")
    bad = [f for f in args.pregrasp_fractions if not 0.0 <= f <= 1.0] + [s for s in args.squeeze_scales if s < 0.0]
    if bad:
        raise SystemExit(f"--pregrasp-fractions in [0, 1], --squeeze-scales >= 0: got {bad}")
    runs = variants(args.pregrasp_fractions, args.squeeze_scales, groups=not args.no_groups)
    tasks = [(args.hand, name, seed, algorithm, plan_fields, runs) for name, seed, algorithm in cases]
    t0 = time.perf_counter()
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as pool:
            rows = list(pool.map(replay_case, tasks))
    else:
        rows = [replay_case(t) for t in tasks]
    labels = [label for label, _, _ in runs]
    table = []
    for label in labels:
        cells = [r["results"].get(label) for r in rows]
        table.append([label, str(sum(bool(c and c["held"]) for c in cells))]
                     + [("H" if c["held"] else ".") + f" {c['shift_mm']:.0f}" if c else "-" for c in cells])
    header = ["variant", f"held of {len(rows)}"] + [
        f"{r['object']}:{r['seed']}" + ("" if r["algorithm"] == "apso" else f" ({r['algorithm']})") for r in rows]
    print(markdown_table(header, table))
    print(f"\n{len(rows)} cases in {time.perf_counter() - t0:.0f} s")
    out = args.out or REPO_ROOT / "bench" / "results" / f"dgb_factors_{Path(args.hand).stem}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"benchmark": "dgb_factors", "hand": args.hand, "dexgraspbench": DEXGRASPBENCH,
                               "groups": GROUPS, "variants": labels, "runs": rows,
                               "command": " ".join(["bench/dgb_factors.py", *(argv or sys.argv[1:])])},
                              indent=1, default=float) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
