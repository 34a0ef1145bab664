"""Turning a general hand's pads to face the surface (issue 21: "pads on the object's surface").

A finger is in contact when its pad sphere touches the object with its pad side
(:mod:`grasp_apso.geometry.any_hand_decoder`), which leaves the pad point
(``Finger.pad_center``) up to the pad radius off the surface when the fingertip touches with
the side of its pad. :func:`align_pads` changes the pre-shape of such fingers (the
particle's joint values: the grasp stays a pre-shape closed along the closing senses) so
that the pad point comes onto the surface. Each round tries, batched over the particles
and fingers (each finger closes on its own), a Gauss-Newton step on the finger's own joints
(the joints no other finger moves; linearised at the grasp posture, the closing parameter
taking up the contact: :func:`pad_step`) at a few fractions, and sampled pre-shapes. A
finger's change is kept only when it is still a legal pad contact with its pad point nearer
the surface; a particle's only when it stays as legal, with as many contacts.

The final selection (:func:`final_decodings`) aligns the fittest grasps of its pool and adds
their strict decodings (``pads_on``: only the contacts whose pad points lie on the surface);
:func:`pads_on` tells the grasps whose every contact's pad point does. Measured on the seven
dex-urdf hands (``bench/unseen_hands.py --quick``): candidates with every pad point within
2 mm 15 -> 88 of 243, contacts 43 % -> 59 %, force closure and the other checks unchanged;
about 0.2 s per plan. Turning the search
itself toward aligned pads (a fitness term, or aligning GRG's draws) found no more of them
and fewer force-closure grasps.
"""

from __future__ import annotations

import numpy as np

from ..geometry import any_hand_kernels as hk
from ..geometry.any_hand_decoder import PAD_ON, AnyDecoded, AnyHandModel, decode_any

__all__ = ["ALIGN_FROM", "align_pads", "pad_step", "final_decodings", "pads_on"]

#: Pad points farther than this from the surface (m) are turned toward it.
ALIGN_FROM = 0.0012
#: Rounds of trials (each decodes the particles to align 3 + SAMPLES + 1 + F times).
ALIGN_ROUNDS = 2
#: Damping of the step (rad^2 per unit residual^2) and the largest change of one joint (rad or m).
DAMPING = 0.02
MAX_STEP = 0.4
#: The fractions of the step tried (one batch).
FRACTIONS = (1.0, 0.5, 0.25)
#: Other pre-shapes tried per round: half near the particle's, half drawn as GRG's.
SAMPLES = 8
LOCAL_SPREAD = 0.1
#: A changed finger's pad sphere is within this of the surface (m; contacts: within the
#: contact tolerance less the grid's margin).
SEATED = 0.001
#: The final selection aligns this many of the fittest grasps per grasp wanted.
ALIGNED_PER_GRASP = 5
#: Finite-difference step of the Jacobian (rad or m).
H = 1e-4
#: A step whose closing hardly moves the pad into the surface (m per unit of s) is skipped.
MIN_APPROACH = 1e-4


def _own_joints(model: AnyHandModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, J) int: each finger's own joints (moved by no other finger; -1 padding), (F, J)
    bool: closing joints among them, (F, J) float: their closing limits."""
    t = model.tables
    users = np.zeros(t.layout.n_joints, dtype=int)
    for f in range(t.n_fingers):
        users[t.j_index[f, :t.j_count[f]]] += 1
    rows = []
    for f in range(t.n_fingers):
        rows.append([(int(t.j_index[f, k]), float(t.j_target[f, k])) for k in range(int(t.j_count[f]))
                     if users[t.j_index[f, k]] == 1])
    width = max(1, max(len(r) for r in rows))
    index = np.full((t.n_fingers, width), -1, dtype=np.int64)
    target = np.full((t.n_fingers, width), np.nan)
    for f, r in enumerate(rows):
        index[f, :len(r)] = [j for j, _ in r]
        target[f, :len(r)] = [v for _, v in r]
    return index, ~np.isnan(target), target


def _pads_object(model: AnyHandModel, root: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pad points and pad sphere centres (P, F, 3) in the object frame from the finger
    link poses (P, F, Lmax, 4, 4) in the root frame and the root poses (P, 4, 4)."""
    t = model.tables
    pad = poses[:, np.arange(t.n_fingers), t.pad_local]                  # (P, F, 4, 4)
    local = np.array([f.pad_center for f in model.hand.fingers], dtype=float)
    out = []
    for pts in (local, np.asarray(t.pad_center, float)):
        r = np.einsum("pfij,fj->pfi", pad[..., :3, :3], pts) + pad[..., :3, 3]
        out.append(np.einsum("pij,pfj->pfi", root[:, :3, :3], r) + root[:, None, :3, 3])
    return out[0], out[1]


def pad_step(model: AnyHandModel, d: AnyDecoded, todo: np.ndarray) -> np.ndarray:
    """The pre-shape change (P, n) that turns the pads of the fingers ``todo`` (P, F) bool
    toward the surface; 0 for the other fingers' joints.

    Linearised at the grasp posture q: a change ``delta`` of the pre-shape moves a closing
    joint by ``(1 - s) delta`` and a pre-shape joint by ``delta``; the closing parameter
    ``s`` moves too, keeping the pad sphere on the surface. The step minimises
    ``|n + g|^2 + DAMPING |delta|^2`` (n the pad normal, g the outward surface normal at the
    pad sphere's centre) to first order.
    """
    t = model.tables
    n_p, n_f = todo.shape
    n_q = d.q.shape[1]
    lmax = t.finger_link.shape[1]
    index, closing, target = _own_joints(model)
    q = np.ascontiguousarray(d.q)
    poses = np.empty((n_p, n_f, lmax, 4, 4))
    hk.link_poses(q, model.kin, poses)
    p0, c0 = _pads_object(model, d.root, poses)
    dp = np.empty((n_q, n_p, n_f, 3))
    dc = np.empty((n_q, n_p, n_f, 3))
    for j in range(n_q):  # only the joints some finger to align owns
        if not np.isin(j, index[todo.any(axis=0)]):
            dp[j] = dc[j] = 0.0
            continue
        qj = q.copy()
        qj[:, j] += H
        hk.link_poses(qj, model.kin, poses)
        pj, cj = _pads_object(model, d.root, poses)
        dp[j], dc[j] = (pj - p0) / H, (cj - c0) / H
    radius = np.asarray(t.pad_radius, float)[None, :, None]
    normal = (p0 - c0) / radius                                            # (P, F, 3)
    dn = (dp - dc) / radius                                                # (n, P, F, 3)
    _, grad = model.sdf.distance_and_gradient(c0.reshape(-1, 3))
    grad = grad.reshape(c0.shape)
    grad /= np.maximum(np.linalg.norm(grad, axis=2, keepdims=True), 1e-12)
    gap = model.sdf.distance(c0.reshape(-1, 3)).reshape(n_p, n_f) - radius[..., 0]
    # The closing direction of every finger: all its closing joints (shared ones too).
    dq_ds = np.zeros((n_p, n_f, n_q))
    for f in range(n_f):
        for k in range(int(t.j_count[f])):
            if not np.isnan(t.j_target[f, k]):
                j = int(t.j_index[f, k])
                dq_ds[:, f, j] = t.j_target[f, k] - d.q_pre[:, j]
    dn_s = np.einsum("jpfi,pfj->pfi", dn, dq_ds)                           # (P, F, 3)
    b = np.einsum("pfi,pfi->pf", np.einsum("jpfi,pfj->pfi", dc, dq_ds), grad)
    step = np.zeros((n_p, n_q))
    rows = np.argwhere(todo & (np.abs(b) > MIN_APPROACH))
    if not len(rows):
        return step
    pr, fr = rows[:, 0], rows[:, 1]
    idx = index[fr]                                                        # (R, J)
    valid = idx >= 0
    safe = np.where(valid, idx, 0)
    scale = np.where(closing[fr], 1.0 - d.closing[pr, fr][:, None], 1.0) * valid   # (R, J)
    cols = dn[safe, pr[:, None], fr[:, None]] * scale[..., None]           # (R, J, 3)
    a = np.einsum("rji,ri->rj", dc[safe, pr[:, None], fr[:, None]], grad[pr, fr]) * scale
    bb = b[pr, fr]
    amat = cols - dn_s[pr, fr][:, None, :] * (a / bb[:, None])[..., None]  # (R, J, 3)
    e = normal[pr, fr] + grad[pr, fr] - dn_s[pr, fr] * (gap[pr, fr] / bb)[:, None]
    lhs = np.einsum("rji,rki->rjk", amat, amat) + DAMPING * np.eye(idx.shape[1])[None]
    rhs = -np.einsum("rji,ri->rj", amat, e)
    delta = np.linalg.solve(lhs, rhs[..., None])[..., 0]
    delta = np.clip(delta, -MAX_STEP, MAX_STEP)
    np.add.at(step, (np.repeat(pr, idx.shape[1]), safe.ravel()), (delta * valid).ravel())
    return step


def _samples(model: AnyHandModel, x: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """k pre-shape variants of every particle x (m, D) -> (k, m, D): half near its
    pre-shape (a Gaussian step of LOCAL_SPREAD of each joint's range), half drawn as GRG
    draws pre-shapes."""
    from .any_hand_grg import _open_fraction, _preshape
    t, lay = model.tables, model.layout
    out = np.repeat(x[None], k, axis=0)
    span = (t.upper - t.lower)[lay.joints]
    near = k // 2
    out[:near, :, lay.joints] += rng.normal(0.0, LOCAL_SPREAD, (near, len(x), len(span))) * span
    far = _preshape(model, (k - near) * len(x), rng, _open_fraction(model))
    out[near:, :, lay.joints] = far.reshape(k - near, len(x), len(span))
    return np.clip(out, t.lower, t.upper)


def align_pads(model: AnyHandModel, x: np.ndarray, rng: np.random.Generator,
               wrist_position: np.ndarray | None = None, rounds: int = ALIGN_ROUNDS,
               samples: int = SAMPLES, decoded: AnyDecoded | None = None) -> tuple[np.ndarray, AnyDecoded]:
    """Particles x (P, D) with the pre-shapes of their pad contacts turned toward the
    surface (see the module docstring), and their decoding (``decoded``: x's, when known).

    Each round tries, for every finger whose pad point is off the surface, the Gauss-Newton
    step (:func:`pad_step`, fractions :data:`FRACTIONS`) and ``samples`` other pre-shapes
    of its own joints (:func:`_samples`), all fingers at once (they close independently):
    each finger takes the variant that keeps a legal pad contact with its pad point nearest
    the surface. A particle takes its fingers' variants together, or when that is less
    legal (fingers now overlapping) the best single finger's, or none.
    """
    t, s = model.tables, model.settings
    lay = t.layout
    x = np.clip(np.asarray(x, dtype=float), t.lower, t.upper)
    d = decode_any(model, x, wrist_position) if decoded is None else decoded
    index, _, _ = _own_joints(model)
    owned = [lay.joints.start + index[f][index[f] >= 0] for f in range(t.n_fingers)]
    for _ in range(rounds):
        todo = d.contact & (d.pad_offset > ALIGN_FROM)
        rows = np.flatnonzero(todo.any(axis=1))
        if not len(rows):
            break
        m, sub = len(rows), d.take(rows)
        step = pad_step(model, sub, todo[rows])
        steps = np.repeat(x[rows][None], len(FRACTIONS), axis=0)
        steps[:, :, lay.joints] += np.asarray(FRACTIONS)[:, None, None] * step[None]
        trial = np.concatenate([np.clip(steps, t.lower, t.upper), _samples(model, x[rows], samples, rng)])
        n_try = len(trial)
        # the trials are scored by their fingers alone: no scene margins
        dt = decode_any(model, trial.reshape(-1, lay.dims), wrist_position, scene_check=False,
                        palm=np.tile(sub.palm_clearance, n_try))
        # A finger changes only to bring its pad point nearer the surface with its pad
        # sphere well seated (not at the edge of the contact tolerance).
        ok = (np.tile(todo[rows], (n_try, 1)) & dt.contact & ~dt.finger_illegal(s.max_penetration)
              & (dt.pad_offset < np.tile(sub.pad_offset, (n_try, 1)) - 1e-4) & (np.abs(dt.tip_gap) <= SEATED))
        score = np.where(ok, dt.pad_offset, np.inf).reshape(n_try, m, -1)
        best = np.argmin(score, axis=0)                                     # (m, F)
        gain = sub.pad_offset - np.min(score, axis=0)                       # (m, F), -inf: none
        better = np.isfinite(gain)
        if not better.any():
            break
        # Every improved finger's variant together; where that is worse for the particle
        # (fingers now overlapping), the finger's that gains most alone.
        joint, single = x[rows].copy(), x[rows].copy()
        top = np.argmax(np.where(better, gain, -np.inf), axis=1)
        for f in range(t.n_fingers):
            sel = np.flatnonzero(better[:, f])
            joint[np.ix_(sel, owned[f])] = trial[best[sel, f], sel][:, owned[f]]
            one = sel[top[sel] == f]
            single[np.ix_(one, owned[f])] = joint[np.ix_(one, owned[f])]
        changed = better.any(axis=1)
        for variant in (joint, single):
            if not changed.any():
                break
            at = np.flatnonzero(changed)
            dv = decode_any(model, variant[at], wrist_position, palm=sub.palm_clearance[at])
            ok = _no_worse(dv, sub.take(at), s.max_penetration)
            x[rows[at[ok]]] = variant[at[ok]]
            d = _replace_rows(d, rows[at[ok]], dv.take(np.flatnonzero(ok)))
            changed[at[ok]] = False
    return x, d


def _no_worse(new: AnyDecoded, old: AnyDecoded, max_penetration: float) -> np.ndarray:
    """(P,) bool: ``new`` keeps as many contacts, is legal where ``old`` was, and its
    contacts' pad points are nearer the surface in sum."""
    near = np.where(new.contact, new.pad_offset, 0.0).sum(axis=1)
    before = np.where(old.contact, old.pad_offset, 0.0).sum(axis=1)
    return ((new.n_contacts >= old.n_contacts) & (new.legal(max_penetration) | ~old.legal(max_penetration))
            & (near < before - 1e-4))


def _replace_rows(d: AnyDecoded, rows: np.ndarray, new: AnyDecoded) -> AnyDecoded:
    """d with its particles ``rows`` replaced by ``new``'s."""
    out = {}
    for name in d.__dataclass_fields__:
        a, b = getattr(d, name), getattr(new, name)
        if a is None:
            out[name] = None
            continue
        a = a.copy()
        a[rows] = b
        out[name] = a
    return AnyDecoded(**out)


def _concat(a: AnyDecoded, b: AnyDecoded) -> AnyDecoded:
    """The particles of a, then b's."""
    return AnyDecoded(**{name: None if getattr(a, name) is None or getattr(b, name) is None
                         else np.concatenate([getattr(a, name), getattr(b, name)])
                         for name in a.__dataclass_fields__})


def align_closable(model: AnyHandModel, x: np.ndarray, rng: np.random.Generator,
                   wrist_position: np.ndarray | None = None, rounds: int = ALIGN_ROUNDS,
                   samples: int = SAMPLES, limit: int | None = None,
                   priority: np.ndarray | None = None,
                   decoded: AnyDecoded | None = None) -> tuple[np.ndarray, AnyDecoded]:
    """:func:`align_pads` of the particles x (P, D) whose grasps can be force closure
    (legal but for the scene, three contacts or more), at most ``limit`` of them, the
    highest ``priority`` (P,) first; the others as they are. Returns the particles and
    their decoding (``decoded``: x's, when known)."""
    s = model.settings
    x = np.clip(np.asarray(x, dtype=float), model.lower, model.upper)
    d = decode_any(model, x, wrist_position) if decoded is None else decoded
    legal = ~d.finger_illegal(s.max_penetration).any(axis=1) & (d.palm_clearance >= -s.max_penetration)
    rows = np.flatnonzero(legal & (d.n_contacts >= 3))
    if limit is not None and len(rows) > limit:
        rank = np.zeros(len(rows)) if priority is None else -np.asarray(priority, float)[rows]
        rows = np.sort(rows[np.argsort(rank, kind="stable")[:limit]])
    if len(rows):
        x[rows], aligned = align_pads(model, x[rows], rng, wrist_position, rounds, samples, d.take(rows))
        d = _replace_rows(d, rows, aligned)
    return x, d


def final_decodings(model: AnyHandModel, problem, x: np.ndarray, wanted: int) -> AnyDecoded:
    """The final selection's decodings of the pool x (P, D): the fittest
    ``ALIGNED_PER_GRASP * wanted`` with their pads turned to the surface
    (:func:`align_closable`), every particle decoded as the search does, then again with
    only the contacts whose pad points lie on the surface (``pads_on``) where that leaves
    another grasp with two or more contacts."""
    wrist = problem.wrist_position
    d = decode_any(model, x, wrist)
    fitness, _ = problem.fitness(d)
    x, d = align_closable(model, x, problem.generator.rng, wrist, limit=ALIGNED_PER_GRASP * wanted,
                          priority=fitness, decoded=d)
    # Only a grasp with a contact whose pad point is off the surface reads otherwise strictly
    # (d is x's decoding, and each particle decodes alone).
    off = np.flatnonzero((d.contact & (d.pad_offset > PAD_ON)).any(axis=1))
    if not len(off):
        return d
    strict = decode_any(model, x[off], wrist, pads_on=True, palm=d.palm_clearance[off])
    other = np.flatnonzero(strict.n_contacts >= 2)
    return _concat(d, strict.take(other)) if len(other) else d


def pads_on(decoded: AnyDecoded) -> np.ndarray:
    """(P,) bool: every contact's pad point of each decoded grasp lies on the surface."""
    return np.all((decoded.pad_offset <= PAD_ON) | ~decoded.contact, axis=1)
