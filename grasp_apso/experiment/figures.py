"""The pictures: Table 3 grids (best grasp at the snapshot iterations, PSO and APSO),
convergence per iteration and per evaluation, and the planner's speed."""

from __future__ import annotations

import math
import os
import tempfile
from typing import Any

import numpy as np

from ..model import builtin as builtin_objects
from ..model.hand import FINGER_NAMES
from ..search.planner import GraspResult, PlanOptions, plan
from .config import _COLORS, ALGORITHM_LABELS, OBJECT_LABELS, ExperimentConfig
from .progress import _log
from .records import valid_grasp
from .stats import _finite, _median_curve, _round, _stats


def _representative_seed(recs: list[dict[str, Any]]) -> int:
    """The seed whose final fitness is the (lower) median of the runs."""
    order = sorted(recs, key=lambda r: (-np.inf if r["fitness"] is None else r["fitness"], r["seed"]))
    return int(order[(len(order) - 1) // 2]["seed"])


def _crop_white(img: np.ndarray, pad: int = 4) -> np.ndarray:
    rgb = img[..., :3]
    mask = (rgb < 0.97).any(axis=-1)
    if img.shape[-1] == 4:
        mask &= img[..., 3] > 0.05
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return img
    r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, img.shape[0])
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, img.shape[1])
    return img[r0:r1, c0:c1]


def _savefig(fig, path: str, dpi: int) -> str:
    """Write a PNG with a 256-colour palette (a third of the size, no visible loss here)."""
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    try:
        from PIL import Image

        buf.seek(0)
        image = Image.open(buf).convert("RGB")
        image.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
            path, optimize=True)
    except Exception:  # pillow comes with matplotlib; fall back to the plain PNG
        with open(path, "wb") as f:
            f.write(buf.getvalue())
    return path


def _grasp_cell(result: GraspResult, obj, hand, path: str, dpi: int) -> np.ndarray:
    """The grasp drawn by ``plotting.plot_grasp`` (fingertip view), legend cut off."""
    import matplotlib.image as mpimg

    from ..tools.plotting import plot_grasp

    plot_grasp(result, obj, path=path, title="", hand=hand, views=("fingertips",), dpi=dpi)
    img = mpimg.imread(path)
    img = img[: int(img.shape[0] * 0.915)]  # drop the legend band (bottom 8 % of the figure)
    return _crop_white(img)


def _caption(result: GraspResult, hand) -> str:
    fingers = ", ".join(c.finger for c in result.contacts) or "none"
    return (f"fitness {result.fitness:.3f}, epsilon {result.epsilon:.3f}\n"
            f"{result.n_contacts} contacts ({fingers})\n"
            f"force closure {'yes' if result.force_closure else 'no'}, "
            f"valid {'yes' if valid_grasp(result, hand) else 'no'}")


def _legend_handles():
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from ..tools.plotting import FINGER_COLORS

    handles = [Line2D([], [], color=FINGER_COLORS[n], linewidth=5, label=n) for n in FINGER_NAMES]
    handles += [
        Line2D([], [], marker="o", color="black", markerfacecolor="white", markeredgewidth=1.5,
               label="contact + surface normal"),
        Line2D([], [], marker="+", linestyle="none", color="#444444", markersize=9, label="centre of mass"),
        Patch(facecolor=(0.62, 0.66, 0.72), alpha=0.5, label="object"),
        Patch(facecolor="#C8A27A", edgecolor="#8A6A4A", alpha=0.6, label="palm"),
        Line2D([], [], color="0.5", alpha=0.3, linewidth=9, solid_capstyle="round", label="finger volume"),
        Line2D([], [], color="black", linewidth=1.3, linestyle=(0, (2, 1.5)),
               label="link touching the object (not a contact)"),
    ]
    return handles


def table3_figures(cfg: ExperimentConfig, runs: dict, out: str, hand) -> tuple[dict, list[dict[str, Any]]]:
    """Per object, the best grasp at the three snapshot iterations for PSO and APSO.

    Returns the picture paths per object and the determinism checks of the re-runs.
    """
    from matplotlib.figure import Figure

    paths: dict[str, Any] = {}
    checks: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in cfg.objects:
            obj = builtin_objects.builtin(name)
            cells: dict[tuple[str, int], tuple[np.ndarray, str]] = {}
            seeds = {}
            for alg in ("pso", "apso"):
                seed = _representative_seed(runs[name][alg])
                seeds[alg] = seed
                main = next(r for r in runs[name][alg] if r["seed"] == seed)
                for k in cfg.snapshots:
                    options = PlanOptions(algorithm=alg, particles=cfg.particles, iterations=k)
                    result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hand)
                    rerun = [_round(h.best_fitness) for h in result.history]
                    rerun_ev = [int(h.evaluations) for h in result.history]
                    same = rerun == main["best_history"][:k] and rerun_ev == main["evaluations_history"][:k]
                    checks.append({"object": name, "algorithm": alg, "seed": seed, "iterations": k,
                                   "prefix_identical": bool(same),
                                   "fitness_rerun": _finite(result.fitness),
                                   "history_best_at_k": main["best_history"][k - 1]})
                    img = _grasp_cell(result, obj, hand, os.path.join(tmp, f"{name}_{alg}_{k}.png"), dpi=70)
                    cells[(alg, k)] = (img, _caption(result, hand))
            fig = Figure(figsize=(13.5, 11.6))
            fig.suptitle(
                f"{OBJECT_LABELS.get(name, name)}: global best grasp at iterations "
                f"{', '.join(map(str, cfg.snapshots))} (np = {cfg.particles})\n"
                f"one run per approach: the seed with the median final fitness over {cfg.seeds} seeds "
                f"(PSO seed {seeds['pso']}, APSO seed {seeds['apso']}); view from beyond the fingertips",
                fontsize=12)
            for row, alg in enumerate(("pso", "apso")):
                for col, k in enumerate(cfg.snapshots):
                    ax = fig.add_axes([0.07 + col * 0.31, 0.585 - row * 0.46, 0.29, 0.335])
                    img, caption = cells[(alg, k)]
                    ax.imshow(img)
                    ax.set_axis_off()
                    ax.set_title(f"iteration {k}", fontsize=11, fontweight="bold")
                    ax.text(0.5, -0.02, caption, transform=ax.transAxes, ha="center", va="top", fontsize=9.5)
                fig.text(0.025, 0.75 - row * 0.46, ALGORITHM_LABELS[alg], rotation=90, ha="center",
                         va="center", fontsize=14, fontweight="bold")
            fig.legend(handles=_legend_handles(), loc="lower center", ncol=6, fontsize=9, frameon=False)
            path = os.path.join(out, f"table3_{name}.png")
            _savefig(fig, path, cfg.dpi)
            paths[name] = os.path.basename(path)
            _log(f"picture {path}")
    return paths, checks


def plot_convergence_panels(cfg: ExperimentConfig, runs: dict, path: str) -> str:
    """Median best fitness per iteration with the inter-quartile band, APSO vs PSO."""
    from matplotlib.figure import Figure

    n = len(cfg.objects)
    ncols = 2 if n > 1 else 1
    nrows = int(math.ceil(n / ncols))
    fig = Figure(figsize=(6.2 * ncols, 4.4 * nrows + 0.6))
    its = np.arange(1, cfg.iterations + 1)
    k20, k50 = cfg.snapshots[1], cfg.snapshots[2]
    for i, name in enumerate(cfg.objects):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        for alg in ("pso", "apso"):
            med, q1, q3 = _median_curve(runs[name][alg], cfg.iterations)
            ax.fill_between(its, q1, q3, color=_COLORS[alg], alpha=0.2, linewidth=0)
            ax.plot(its, med, color=_COLORS[alg], linewidth=2.2,
                    label=f"{ALGORITHM_LABELS[alg]}: median (final {med[-1]:.3f})")
        pso_med = _median_curve(runs[name]["pso"], cfg.iterations)[0]
        apso_med = _median_curve(runs[name]["apso"], cfg.iterations)[0]
        ax.axhline(pso_med[k50 - 1], color=_COLORS["pso"], linestyle=":", linewidth=1.2)
        ax.plot([k20], [apso_med[k20 - 1]], marker="o", color=_COLORS["apso"], markersize=7,
                markeredgecolor="black", linestyle="none",
                label=f"APSO at iteration {k20}: {apso_med[k20 - 1]:.3f} vs PSO at {k50}: {pso_med[k50 - 1]:.3f}")
        for k in cfg.snapshots:
            ax.axvline(k, color="0.75", linewidth=0.8, zorder=0)
        lows = [_median_curve(runs[name][a], cfg.iterations)[j][min(4, cfg.iterations - 1):]
                for a in ("pso", "apso") for j in (0, 1)]
        ax.set_ylim(bottom=float(np.nanmin(np.concatenate(lows))) - 0.03)
        ax.set_title(OBJECT_LABELS.get(name, name), fontsize=11)
        ax.set_xlabel("iteration")
        ax.set_ylabel("global best fitness (maximised)")
        ax.set_xlim(1, cfg.iterations)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower right", fontsize=8.5)
    fig.suptitle(f"Convergence over {cfg.seeds} seeds (np = {cfg.particles}): median global best fitness, "
                 "band = inter-quartile range;\ndotted line: PSO's median at the last iteration; grey lines: "
                 f"iterations {', '.join(map(str, cfg.snapshots))}; the y axis starts near the lowest quartile "
                 f"from iteration {min(5, cfg.iterations)} on", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    _savefig(fig, path, cfg.dpi)
    return path


def _curve_on_evaluations(recs: list[dict[str, Any]], grid: np.ndarray) -> tuple[np.ndarray, ...]:
    """Median and quartiles of the best fitness found within ``grid`` evaluations.

    A run that ended keeps its final best (it found it within fewer evaluations); the
    curve stops at the median of the runs' final evaluation counts; before a run's first
    recorded iteration (GRG's initial draws cost evaluations) it has no value.
    """
    import warnings

    rows = []
    for r in recs:
        ev = np.asarray(r["evaluations_history"], float)
        best = np.array([np.nan if v is None else v for v in r["best_history"]], float)
        idx = np.searchsorted(ev, grid, side="right") - 1
        rows.append(np.where(idx >= 0, best[np.clip(idx, 0, None)], np.nan))
    arr = np.array(rows)
    end = float(np.median([r["evaluations_history"][-1] for r in recs]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        enough = (np.sum(np.isfinite(arr), axis=0) >= max(1, (len(recs) + 1) // 2)) & (grid <= end * 1.0001)
        out = [np.where(enough, np.nanpercentile(arr, q, axis=0), np.nan) for q in (50, 25, 75)]
    return tuple(out)


def plot_evaluation_panels(cfg: ExperimentConfig, runs: dict, path: str) -> str:
    """Median best fitness against evaluations: APSO, PSO on APSO's budget, pyswarms."""
    from matplotlib.figure import Figure

    n = len(cfg.objects)
    ncols = 2 if n > 1 else 1
    nrows = int(math.ceil(n / ncols))
    fig = Figure(figsize=(6.2 * ncols, 4.4 * nrows + 0.6))
    for i, name in enumerate(cfg.objects):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        top = max(max(r["evaluations_history"][-1] for r in recs) for recs in runs[name].values())
        grid = np.linspace(cfg.particles, top, 400)
        lows: list[float] = []
        for alg in ("apso", "pso_equal_budget", "pso", "pyswarms_global", "pyswarms_local"):
            if alg not in runs[name]:
                continue
            med, q1, q3 = _curve_on_evaluations(runs[name][alg], grid)
            style = "--" if alg == "pso" else "-"
            if alg in ("apso", "pso_equal_budget"):
                ax.fill_between(grid, q1, q3, color=_COLORS[alg], alpha=0.15, linewidth=0)
            final = _stats([r["fitness"] for r in runs[name][alg]])["median"]
            label = f"{ALGORITHM_LABELS[alg]}" + (f" (final median {final:.3f})" if final is not None else "")
            if alg in ("apso", "pso"):
                start = max(len(med) // 10, 1)
                lows.append(np.nanmin(np.where(np.isfinite(q1[start:]), q1[start:], np.inf)))
            ax.plot(grid, med, color=_COLORS[alg], linewidth=2.0, linestyle=style, label=label)
        ax.set_title(OBJECT_LABELS.get(name, name), fontsize=11)
        if lows and np.isfinite(min(lows)):
            ax.set_ylim(bottom=float(min(lows)) - 0.03)
        ax.set_xlabel("evaluations (particle decodes, GRG draws included)")
        ax.set_ylabel("global best fitness (maximised)")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower right", fontsize=8.5)
    fig.suptitle(f"Fitness against evaluations over {cfg.seeds} seeds (np = {cfg.particles}): median, band = "
                 "inter-quartile range (APSO and PSO on APSO's budget);\nthe y axis starts near the lowest "
                 "APSO/PSO quartile after the first tenth of the budget", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    _savefig(fig, path, cfg.dpi)
    return path


def plot_speed(speed: dict[str, Any], path: str, dpi: int = 100) -> str:
    """Plan time against particles, iterations and mesh triangles (one figure, 3 panels)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(15.0, 4.8))
    cfg = speed["config"]
    for i, (key, fixed) in enumerate((("particles", "nit = 50"), ("iterations", "np = 60"))):
        ax = fig.add_subplot(1, 3, i + 1)
        for alg in ("apso", "pso"):
            pts = sorted((e[key], e["planning_time"]) for e in speed[key] if e["algorithm"] == alg)
            xs = [p[0] for p in pts]
            med = [p[1]["median"] for p in pts]
            lo = [p[1]["median"] - p[1]["min"] for p in pts]
            hi = [p[1]["max"] - p[1]["median"] for p in pts]
            ax.errorbar(xs, med, yerr=[lo, hi], marker="o", capsize=3, color=_COLORS[alg],
                        label=f"{ALGORITHM_LABELS[alg]} (median, bars min-max)")
        ax.axhline(0.3, color="0.4", linestyle=":", linewidth=1.2, label="0.3 s target (np 60, nit 50)")
        ax.set_xlabel(f"number of {key}")
        ax.set_ylabel("plan time (s)")
        ax.set_title(f"plan time vs {key} ({cfg['sweep_object']}, {fixed}, {cfg['repeats']} run(s) per point)",
                     fontsize=10)
        ax.set_xticks(sorted({e[key] for e in speed[key]}))
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8.5, loc="upper left")
    ax = fig.add_subplot(1, 3, 3)
    ms = sorted(speed["meshes"], key=lambda m: m["triangles"])
    tri = [m["triangles"] for m in ms]
    for key, label, color, style in (
        ("preparation_time", "preparation (signed-distance grid)", "#009E73", "o-"),
        ("plan_time_warm", "plan, warm (geometry prepared)", _COLORS["apso"], "s-"),
        ("prep_plus_plan", "preparation + first plan", "#000000", "^--"),
        ("construction_time", "object construction (mesh validation)", "#999999", "v:"),
    ):
        ax.plot(tri, [m[key] for m in ms], style, color=color, label=label)
    ax.axhline(1.0, color="0.4", linestyle=":", linewidth=1.2, label="1 s target incl. preparation (10k triangles)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(tri)
    ax.set_xticklabels([f"{t / 1000:.1f}k" if t < 10_000 else f"{t / 1000:.0f}k" for t in tri])
    ax.minorticks_off()
    ax.grid(True, which="major", alpha=0.3)
    ax.set_xlabel("mesh triangles (5 cm spheres)")
    ax.set_ylabel("time (s)")
    ax.set_title("time vs mesh size (APSO, np = 60, nit = 50)", fontsize=10)
    ax.legend(fontsize=8, loc="best")
    fig.suptitle("Planner speed on this machine", fontsize=12)
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    _savefig(fig, path, dpi)
    return path
