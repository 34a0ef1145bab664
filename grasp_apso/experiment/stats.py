"""Statistics over seeds: finite values, median and quartiles, rates, median curves of the
best fitness per iteration and the one-sided Mann-Whitney test."""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np


def _finite(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _round(x: float, digits: int = 6) -> float | None:
    x = _finite(x)
    return None if x is None else round(x, digits)


def _stats(values: Sequence[float | None]) -> dict[str, Any]:
    """median, quartiles, min, max, mean and n of the finite values."""
    arr = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if arr.size == 0:
        return {"n": 0, "median": None, "q1": None, "q3": None, "min": None, "max": None, "mean": None}
    q1, med, q3 = np.percentile(arr, [25, 50, 75])
    return {"n": int(arr.size), "median": float(med), "q1": float(q1), "q3": float(q3),
            "min": float(arr.min()), "max": float(arr.max()), "mean": float(arr.mean())}


def _rate(flags: Sequence[bool]) -> float | None:
    return float(np.mean(flags)) if len(flags) else None


def _median_curve(recs: list[dict[str, Any]], length: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows = []
    for r in recs:
        h = [np.nan if v is None else v for v in r["best_history"][:length]]
        h += [h[-1] if h else np.nan] * (length - len(h))  # a stopped run keeps its best
        rows.append(h)
    arr = np.array(rows, dtype=float)
    with np.errstate(all="ignore"):
        return tuple(np.nanpercentile(arr, q, axis=0) for q in (50, 25, 75))  # type: ignore[return-value]


def _mannwhitney(a: Sequence[float], b: Sequence[float]) -> float | None:
    """One-sided p-value that ``a`` tends to be larger than ``b`` (Mann-Whitney U)."""
    a = [x for x in a if x is not None]
    b = [x for x in b if x is not None]
    if len(a) < 2 or len(b) < 2:
        return None
    try:
        from scipy.stats import mannwhitneyu

        return float(mannwhitneyu(a, b, alternative="greater").pvalue)
    except Exception:  # pragma: no cover - scipy is a dependency
        return None
