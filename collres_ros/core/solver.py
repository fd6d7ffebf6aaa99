"""Sequential impulses over all contacts, vectorised by graph colouring.

Velocities of the N bodies live in one (N, 6) array: linear velocity of the
centre of mass (m/s) then angular velocity (rad/s), world frame. Each contact
has three constraint rows: the normal n (unit, from A to B) and two unit
tangents t1, t2 (n, t1, t2 right-handed). An impulse lambda on a row is
applied to B along +d and to A along -d at the contact point, so equal and
opposite impulses conserve linear and angular momentum by construction.

Relative velocity of a row: ``(v_B + w_B x r_B - v_A - w_A x r_A) . d``
(negative normal component = approaching), ``r`` the contact point minus the
body's centre of mass.

Contacts are grouped by body pair (a manifold: up to a few points of one
face contact). The pairs are greedily coloured so that no movable body is in
two pairs of one colour; rows are sorted by colour, and each colour is solved
at once with numpy: Gauss-Seidel across colours, and within a manifold
Jacobi with mass splitting (each of the k points of a pair acts on 1/k of
each body's mass, and the k impulses are summed: Tonge et al. 2012), which is
exact for one point and converges for face contacts without a loop per point.
Immovable bodies (static or inactive) have zero inverse mass and inertia and
may appear in any number of pairs of a colour: their velocity never
changes. Stages, as in Box2D v3: prepare, warm start, solve (iterate),
restitution, store impulses; plus a split-impulse position stage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from collres_ros.core.types import ContactState

_TINY = 1e-12


@dataclass
class ContactRows:
    """Per-contact constants of one step, rows sorted by colour (see ``order``).

    Every per-contact array is in colour order; ``order[k]`` is the index of
    row k in the caller's contact arrays.
    """

    order: np.ndarray          # (M,) int, caller index of each row
    batches: list[slice]       # one slice per colour
    pair: np.ndarray           # (M, 2) int, body indices A, B
    basis: np.ndarray          # (M, 3, 3) rows n, t1, t2, unit, world
    jacobian: np.ndarray       # (M, 3, 12) relative velocity of each row = J . [vA wA vB wB]
    response: np.ndarray       # (M, 12, 3) velocity change per unit row impulse, M^-1 J^T
    normal_mass: np.ndarray    # (M,) kg, 1 / (J_n M^-1 J_n^T); 0 when both are immovable
    tangent_block: np.ndarray  # (M, 2, 2) 1/kg, tangential Delassus block J_t M^-1 J_t^T
    coupling: np.ndarray       # (M, 2) m/s per N s: tangential velocity per normal impulse
    approach: np.ndarray       # (M,) m/s, pre-solve normal relative velocity (< 0 approaching)
    allowance: np.ndarray      # (M,) m/s >= 0, approach speed allowed without impulse
    bounce: np.ndarray         # (M,) bool, approach faster than the restitution threshold
    restitution_a: np.ndarray  # (M,) e applied to A's impulse
    restitution_b: np.ndarray  # (M,) e applied to B's impulse (equal unless per_object)
    mu: np.ndarray             # (M,) friction coefficient of the cone this step
    sticking: np.ndarray       # (M,) bool, slow enough to stick: mu is the static coefficient

    @property
    def count(self) -> int:
        return int(self.pair.shape[0])


@dataclass
class Impulses:
    """Accumulated impulses of the rows (N s), in colour order."""

    normal: np.ndarray        # (M,) >= 0, from the iterations (what is warm started)
    tangent: np.ndarray       # (M, 2) along t1, t2, |.| <= mu * normal
    restitution: np.ndarray   # (M, 2) extra normal impulse on A, on B from the restitution pass

    @staticmethod
    def zeros(count: int) -> 'Impulses':
        return Impulses(np.zeros(count), np.zeros((count, 2)), np.zeros((count, 2)))


def tangent_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents t1, t2 with (n, t1, t2) right-handed; defined for every unit n."""
    axis = np.eye(3)[np.argmin(np.abs(normal), axis=1)]
    t1 = np.cross(normal, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)   # >= sqrt(2/3) for a unit normal
    return t1, np.cross(normal, t1)


def colour_pairs(pair: np.ndarray, movable: np.ndarray) -> np.ndarray:
    """Colour per contact: no movable body in two different pairs of one colour.

    Greedy over the distinct pairs with one bitmask of used colours per body.
    """
    count = movable.shape[0]
    key = pair[:, 0] * count + pair[:, 1]
    keys, which = np.unique(key, return_inverse=True)
    masks = [0] * count
    move = movable.tolist()
    colours = []
    for k in keys.tolist():
        a, b = divmod(k, count)
        used = (masks[a] if move[a] else 0) | (masks[b] if move[b] else 0)
        bit = ~used & (used + 1)            # lowest free colour
        colours.append(bit.bit_length() - 1)
        if move[a]:
            masks[a] |= bit
        if move[b]:
            masks[b] |= bit
    return np.asarray(colours, np.int64)[which]


def prepare(pair: np.ndarray, normal: np.ndarray, r_a: np.ndarray, r_b: np.ndarray,
            inv_mass: np.ndarray, inv_inertia: np.ndarray, velocity: np.ndarray,
            allowance: np.ndarray, restitution: tuple[np.ndarray, np.ndarray],
            friction: tuple[np.ndarray, np.ndarray], threshold: float,
            sticking_speed: float, sticking_velocity: np.ndarray | None = None,
            jacobi: bool = False) -> ContactRows:
    """Constraint rows of M contacts.

    pair (M, 2) body indices; normal (M, 3) unit, A to B; r_a, r_b (M, 3) m,
    contact point minus each centre of mass; inv_mass (N,) 1/kg and
    inv_inertia (N, 3, 3) world frame, both zero for immovable bodies;
    velocity (N, 6) pre-solve; allowance (M,) m/s approach allowed without
    impulse; restitution (e on A, e on B); friction (mu_static, mu_kinetic);
    threshold m/s (restitution above it); a contact whose tangential speed is
    below ``sticking_speed`` (m/s) may stick: that speed is measured with
    ``sticking_velocity`` (N, 6), e.g. the velocities before this step's
    external forces, default ``velocity``. ``jacobi``: one batch for all
    rows (Jacobi with mass splitting) instead of coloured pairs.
    """
    pair = np.asarray(pair, np.int64).reshape(-1, 2)
    count = inv_mass.shape[0]
    if jacobi:
        colour = np.zeros(pair.shape[0], np.int64)
    else:
        colour = colour_pairs(pair, inv_mass > 0.0)
    order = np.argsort(colour, kind='stable')
    edges = np.searchsorted(colour[order], np.arange(colour.max() + 2 if colour.size else 1))
    batches = [slice(int(lo), int(hi)) for lo, hi in zip(edges[:-1], edges[1:]) if hi > lo]
    # mass splitting: rows of a batch that act on each body (k), per side of each row
    share = np.empty((pair.shape[0], 2))
    for batch in batches:
        sub = pair[order[batch]]
        rows_of = np.bincount(sub.ravel(), minlength=count)
        share[order[batch]] = rows_of[sub]

    pair, normal, r_a, r_b = pair[order], normal[order], r_a[order], r_b[order]
    t1, t2 = tangent_basis(normal)
    basis = np.stack((normal, t1, t2), axis=1)                 # (M, 3, 3)
    arm_a = np.cross(r_a[:, None, :], basis)                   # r_A x d per row
    arm_b = np.cross(r_b[:, None, :], basis)
    jacobian = np.concatenate((-basis, -arm_a, basis, arm_b), axis=2)
    ma, mb = inv_mass[pair[:, 0]], inv_mass[pair[:, 1]]
    ia, ib = inv_inertia[pair[:, 0]], inv_inertia[pair[:, 1]]
    response = np.concatenate((
        -ma[:, None, None] * basis.transpose(0, 2, 1), -ia @ arm_a.transpose(0, 2, 1),
        mb[:, None, None] * basis.transpose(0, 2, 1), ib @ arm_b.transpose(0, 2, 1)), axis=1)
    # Delassus block of each row, each body's mass split over the rows of the batch on it
    share = share[order]
    delassus = (jacobian[:, :, :6] @ response[:, :6, :]) * share[:, 0, None, None] \
        + (jacobian[:, :, 6:] @ response[:, 6:, :]) * share[:, 1, None, None]
    k_n = delassus[:, 0, 0]
    normal_mass = np.where(k_n > _TINY, 1.0 / np.where(k_n > _TINY, k_n, 1.0), 0.0)
    relative = _row_velocity(jacobian, velocity, pair)
    slow = relative if sticking_velocity is None else \
        _row_velocity(jacobian, sticking_velocity, pair)
    approach = relative[:, 0]
    sticking = np.hypot(slow[:, 1], slow[:, 2]) < sticking_speed
    return ContactRows(
        order=order, batches=batches, pair=pair, basis=basis, jacobian=jacobian,
        response=response, normal_mass=normal_mass, tangent_block=delassus[:, 1:, 1:],
        coupling=delassus[:, 1:, 0], approach=approach,
        allowance=np.asarray(allowance, float)[order],
        bounce=approach < -threshold,
        restitution_a=np.asarray(restitution[0], float)[order],
        restitution_b=np.asarray(restitution[1], float)[order],
        mu=np.where(sticking, np.asarray(friction[0], float)[order],
                    np.asarray(friction[1], float)[order]),
        sticking=sticking)


def _row_velocity(jacobian: np.ndarray, velocity: np.ndarray, pair: np.ndarray) -> np.ndarray:
    """Relative velocity (M, 3) along n, t1, t2 (m/s)."""
    stacked = velocity[pair].reshape(-1, 12)
    return np.einsum('mdj,mj->md', jacobian, stacked)


def _apply(rows: ContactRows, velocity: np.ndarray, rows_slice: slice,
           delta: np.ndarray) -> None:
    """Add the velocity change of row impulses ``delta`` (m, 3) to the bodies (summed)."""
    change = np.einsum('mjd,md->mj', rows.response[rows_slice], delta)
    np.add.at(velocity, rows.pair[rows_slice].ravel(), change.reshape(-1, 6))


def warm_start(rows: ContactRows, impulses: Impulses, velocity: np.ndarray) -> None:
    """Apply last step's accumulated impulses (already projected on this step's rows)."""
    if rows.count:
        delta = np.concatenate((impulses.normal[:, None], impulses.tangent), axis=1)
        _apply(rows, velocity, slice(None), delta)


def solve_velocities(rows: ContactRows, impulses: Impulses, velocity: np.ndarray,
                     iterations: int) -> None:
    """Sequential impulses: normal clamped >= 0, friction clamped to the circular cone."""
    for _ in range(iterations):
        for batch in rows.batches:
            _solve_batch(rows, impulses, velocity, batch)


def _solve_batch(rows: ContactRows, impulses: Impulses, velocity: np.ndarray,
                 s: slice) -> None:
    stacked = velocity[rows.pair[s]].reshape(-1, 12)
    rel = np.einsum('mdj,mj->md', rows.jacobian[s], stacked)
    # normal: approach no faster than the speculative allowance, accumulated impulse >= 0
    old_n = impulses.normal[s]
    new_n = np.maximum(old_n - rows.normal_mass[s] * (rel[:, 0] + rows.allowance[s]), 0.0)
    d_n = new_n - old_n
    # friction: oppose the tangential slip left after the normal change (the lecture's
    # tangent, v_t / |v_t|), as much as stops it along that direction, within mu * j_n
    v_t = rel[:, 1:] + rows.coupling[s] * d_n[:, None]
    old_t = impulses.tangent[s]
    trial = old_t - v_t * _slip_mass(rows.tangent_block[s], v_t)[:, None]
    limit = rows.mu[s] * new_n
    size = np.hypot(trial[:, 0], trial[:, 1])
    over = size > limit
    scale = np.where(over, limit / np.where(over, size, 1.0), 1.0)
    new_t = trial * scale[:, None]
    delta = np.concatenate((d_n[:, None], new_t - old_t), axis=1)   # before old_* (views) change
    impulses.normal[s] = new_n
    impulses.tangent[s] = new_t
    _apply(rows, velocity, s, delta)


def _slip_mass(block: np.ndarray, v_t: np.ndarray) -> np.ndarray:
    """|v_t|^2 / (v_t^T K_t v_t): impulse per unit slip speed along -v_t; 0 when v_t = 0."""
    speed2 = np.einsum('mi,mi->m', v_t, v_t)
    k = np.einsum('mi,mij,mj->m', v_t, block, v_t)
    ok = k > _TINY * np.maximum(speed2, _TINY)
    return np.where(ok, speed2 / np.where(ok, k, 1.0), 0.0)


def apply_restitution(rows: ContactRows, impulses: Impulses, velocity: np.ndarray) -> None:
    """One pass: bouncing contacts leave at -e times their pre-solve approach speed.

    Only contacts that approached faster than the threshold and carry a
    normal impulse bounce; A's and B's extra impulses use their own e (equal
    unless the per_object rule is chosen), each keeping the total >= 0.
    """
    for s in rows.batches:
        active = rows.bounce[s] & (impulses.normal[s] > 0.0)
        if not active.any():
            continue
        stacked = velocity[rows.pair[s]].reshape(-1, 12)
        v_n = np.einsum('mj,mj->m', rows.jacobian[s, 0, :], stacked)
        total = impulses.normal[s]
        mass = rows.normal_mass[s]
        pre = rows.approach[s]
        d_a = np.where(active, np.maximum(-mass * (v_n + rows.restitution_a[s] * pre), -total),
                       0.0)
        d_b = np.where(active, np.maximum(-mass * (v_n + rows.restitution_b[s] * pre), -total),
                       0.0)
        impulses.restitution[s] = np.stack((d_a, d_b), axis=1)
        response = rows.response[s, :, 0]                      # (m, 12)
        change = np.concatenate((response[:, :6] * d_a[:, None],
                                 response[:, 6:] * d_b[:, None]), axis=1)
        np.add.at(velocity, rows.pair[s].ravel(), change.reshape(-1, 6))


def solve_positions(rows: ContactRows, push: np.ndarray, count: int,
                    iterations: int) -> np.ndarray:
    """Split-impulse push-out: pseudo velocities (N, 6) that remove ``push`` (m/s per row).

    The pseudo velocity is applied to the poses only (times dt by the caller)
    and never fed into the real velocities, so it adds no energy. Rows with
    push 0 still keep the pseudo motion from driving contacts deeper.
    """
    pseudo = np.zeros((count, 6))
    if not rows.count or not np.any(push > 0.0):
        return pseudo
    accumulated = np.zeros(rows.count)
    for _ in range(iterations):
        for s in rows.batches:
            stacked = pseudo[rows.pair[s]].reshape(-1, 12)
            v_n = np.einsum('mj,mj->m', rows.jacobian[s, 0, :], stacked)
            old = accumulated[s]
            new = np.maximum(old + rows.normal_mass[s] * (push[s] - v_n), 0.0)
            change = rows.response[s, :, 0] * (new - old)[:, None]
            accumulated[s] = new
            np.add.at(pseudo, rows.pair[s].ravel(), change.reshape(-1, 6))
    return pseudo


def friction_world(rows: ContactRows, impulses: Impulses) -> np.ndarray:
    """Friction impulse vectors (M, 3), N s, world, applied to B (colour order)."""
    return np.einsum('mi,mij->mj', impulses.tangent, rows.basis[:, 1:, :])


def project_friction(rows: ContactRows, friction: np.ndarray) -> np.ndarray:
    """World friction impulses (M, 3) in colour order onto this step's tangents (M, 2)."""
    return np.einsum('mij,mj->mi', rows.basis[:, 1:, :], friction)


def contact_states(rows: ContactRows, impulses: Impulses, velocity: np.ndarray,
                   sticking_speed: float) -> np.ndarray:
    """State per row (colour order), the first rule that applies.

    IMPACT: approached faster than the restitution threshold and was pushed
    (normal impulse > 0). SLIDING: slid faster than ``sticking_speed`` before
    the step (kinetic coefficient) or after solving, or the friction reached
    the static cone (it broke away). STICKING: a non-zero friction impulse
    inside the static cone held it. RESTING: otherwise (no friction needed).
    """
    rel = _row_velocity(rows.jacobian, velocity, rows.pair)
    size = np.hypot(impulses.tangent[:, 0], impulses.tangent[:, 1])
    friction = size > _TINY
    touching = impulses.normal > 0.0
    at_limit = size >= rows.mu * impulses.normal * (1.0 - 1e-9)
    sliding = (np.hypot(rel[:, 1], rel[:, 2]) > sticking_speed) | ~rows.sticking \
        | (friction & at_limit)
    state = np.full(rows.count, int(ContactState.RESTING), np.uint8)
    state[friction] = ContactState.STICKING
    state[touching & sliding & (friction | (rows.mu == 0.0))] = ContactState.SLIDING
    state[rows.bounce & touching] = ContactState.IMPACT
    return state
