"""The leaders' archive: the best distinct grasps the swarm has evaluated (issue 12).

The paper's future work: keep the swarm's leaders as a list of good grasps. Every
evaluation of the swarm (APSO and the simple PSO alike, the same code path) offers its
particles with their fitness; the archive keeps the fittest *distinct* active ones, up
to ``capacity``. Two grasps are distinct when their wrists (palm frames, object frame)
differ by at least ``min_orientation_gap`` (rad, the angle of the relative rotation) OR
by at least ``min_position_gap`` (m); a grasp is dropped when a fitter one lies within
both gaps (greedy non-maximum suppression in descending fitness, a compiled loop).

The archive only observes: it draws no random numbers and changes no particle, so the
swarm's result is the same with or without it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["LeaderArchive", "wrists_distinct", "wrist_groups"]


@numba.njit(cache=True, nogil=True)
def _suppress(rot, pos, order, cos_gap, pos_gap2, capacity, keep):
    """Greedy selection in ``order`` (descending fitness): keep[i] when i is distinct from
    every kept one; at most ``capacity`` kept. rot (N, 3, 3), pos (N, 3); returns the count."""
    chosen = np.empty(capacity, dtype=np.int64)
    count = 0
    for oi in range(order.shape[0]):
        i = order[oi]
        distinct = True
        for c in range(count):
            j = chosen[c]
            dx = pos[i, 0] - pos[j, 0]
            dy = pos[i, 1] - pos[j, 1]
            dz = pos[i, 2] - pos[j, 2]
            if dx * dx + dy * dy + dz * dz >= pos_gap2:
                continue
            trace = 0.0
            for a in range(3):
                for b in range(3):
                    trace += rot[i, a, b] * rot[j, a, b]
            if 0.5 * (trace - 1.0) <= cos_gap:  # angle >= gap
                continue
            distinct = False
            break
        keep[i] = distinct
        if distinct:
            chosen[count] = i
            count += 1
            if count == capacity:
                break
    return count


def distinct_mask(rot: np.ndarray, pos: np.ndarray, fitness: np.ndarray, capacity: int,
                  min_orientation_gap: float, min_position_gap: float) -> np.ndarray:
    """Which of N wrists (rot (N, 3, 3), pos (N, 3) m, fitness (N,)) survive greedy
    suppression in descending fitness (ties: the earlier first): (N,) bool, at most
    ``capacity`` True."""
    order = np.argsort(-np.asarray(fitness, dtype=float), kind="stable").astype(np.int64)
    keep = np.zeros(len(order), dtype=bool)
    if capacity > 0 and len(order):
        _suppress(np.ascontiguousarray(rot, dtype=np.float64), np.ascontiguousarray(pos, dtype=np.float64),
                  order, math.cos(min_orientation_gap), min_position_gap ** 2, int(capacity), keep)
    return keep


def wrists_distinct(rot_a: np.ndarray, pos_a: np.ndarray, rot_b: np.ndarray, pos_b: np.ndarray,
                    min_orientation_gap: float, min_position_gap: float) -> np.ndarray:
    """Whether wrist a (3, 3), (3,) is distinct from each of wrists b (N, 3, 3), (N, 3): (N,) bool."""
    trace = np.einsum("ab,nab->n", rot_a, rot_b)
    angle = np.arccos(np.clip(0.5 * (trace - 1.0), -1.0, 1.0))
    return (angle >= min_orientation_gap) | (np.linalg.norm(pos_b - pos_a, axis=1) >= min_position_gap)


def wrist_groups(rot: np.ndarray, pos: np.ndarray, min_orientation_gap: float,
                 min_position_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """Groups of like wrists, in order: wrist i (rot (N, 3, 3), pos (N, 3) m) leads a new
    group when it is distinct (:func:`wrists_distinct`) from every earlier group's leader,
    else it joins the first of them it is not distinct from. Returns (group (N,) int,
    numbered in order of their leaders; member (N,) int, 0 for a leader, then 1, 2, ... in
    the group's order)."""
    group = np.empty(len(rot), dtype=np.int64)
    member = np.empty(len(rot), dtype=np.int64)
    leaders: list[int] = []
    sizes: list[int] = []
    for i in range(len(rot)):
        like = np.flatnonzero(~wrists_distinct(rot[i], pos[i], rot[leaders], pos[leaders], min_orientation_gap,
                                               min_position_gap)) if leaders else ()
        if len(like):
            group[i], member[i] = like[0], sizes[like[0]]
            sizes[like[0]] += 1
        else:
            group[i], member[i] = len(leaders), 0
            leaders.append(i)
            sizes.append(1)
    return group, member


class LeaderArchive:
    """The fittest distinct active particles seen so far (see the module docstring).

    Parameters
    ----------
    capacity : int
        Most entries kept (the planner uses 4 * max_grasps).
    min_orientation_gap : float, rad
    min_position_gap : float, m
    """

    def __init__(self, capacity: int, min_orientation_gap: float, min_position_gap: float):
        if capacity < 1:
            raise ValueError(f"capacity: expected at least 1, got {capacity}")
        self.capacity = int(capacity)
        self.min_orientation_gap = float(min_orientation_gap)
        self.min_position_gap = float(min_position_gap)
        self.x = np.empty((0, 0))
        self.fitness = np.empty(0)
        self.rot = np.empty((0, 3, 3))
        self.pos = np.empty((0, 3))

    def __len__(self) -> int:
        return len(self.fitness)

    def offer(self, x: np.ndarray, fitness: np.ndarray, active: np.ndarray, wrist: np.ndarray) -> None:
        """Offer evaluated particles.

        x : (P, D) float; fitness : (P,) float; active : (P,) bool (only active ones are
        kept); wrist : (P, 4, 4) float, palm frames in the object frame.
        """
        take = np.asarray(active, dtype=bool) & np.isfinite(fitness)
        if not take.any():
            return
        x_new = np.asarray(x, dtype=float)[take]
        if self.x.size == 0:
            self.x = np.empty((0, x_new.shape[1]))
        xs = np.concatenate([self.x, x_new])
        fs = np.concatenate([self.fitness, np.asarray(fitness, dtype=float)[take]])
        rs = np.concatenate([self.rot, wrist[take, :3, :3]])
        ps = np.concatenate([self.pos, wrist[take, :3, 3]])
        keep = distinct_mask(rs, ps, fs, self.capacity, self.min_orientation_gap, self.min_position_gap)
        order = np.flatnonzero(keep)
        order = order[np.argsort(-fs[order], kind="stable")]
        self.x, self.fitness, self.rot, self.pos = xs[order], fs[order], rs[order], ps[order]
