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

Contacts are grouped by body pair (a manifold: the points of one face
contact). The pairs are greedily coloured so that no movable body is in two
pairs of one colour (beyond MAX_COLOURS colours, pairs share a colour and
their bodies' masses are split between them: Tonge et al. 2012); rows are
sorted by colour and pair, padded to K points per pair, and each colour is
solved at once with numpy: Gauss-Seidel across colours, Jacobi over the K
points of a pair with a step factor 1 / lambda_max of the pair's normalised
Delassus matrix, so the joint step never overshoots (a box face's support is
found in one iteration). Friction of a point acts along minus its slip
velocity (the classic unit tangent), clamped to the circular cone mu * j_n.
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
MAX_COLOURS = 8   # more colours are merged (mass splitting); bounds the batches per iteration
MAX_POINTS = 4    # rows of one pair solved jointly; bigger manifolds are cut into chunks
MIN_PAIRS = 16    # a colour with fewer groups is merged into the previous one ...
KEEP_COLOURS = 3  # ... except the first ones
CONVERGED = 1e-4  # a sweep that changes every impulse by less than this (relative) ends iterating


@dataclass
class Batch:
    """One colour: its P distinct pairs, each padded to K rows (padding rows do nothing).

    Per-row constants are copied into (P, K, ...) arrays so that one numpy call
    handles every point of every pair of the colour; the accumulated impulses
    of the colour live here while iterating.
    """

    pairs: np.ndarray          # (P, 2) body indices A, B
    slot: np.ndarray           # (P, K) row index (colour order), M for padding
    unique: bool               # no movable body twice: scatter by direct assignment
    jacobian: np.ndarray       # (P, K * 3, 12) rows n, t1, t2 of each point
    response: np.ndarray       # (P, 12, K * 3) pair velocity change per row impulse
    normal_jacobian: np.ndarray  # (P, K, 12) the normal rows only
    normal_response: np.ndarray  # (P, 12, K)
    normal_mass: np.ndarray    # (P, K) kg, step factor / A_ii
    tangent_quad: np.ndarray   # (3, P, K) 1/kg, K_t11, K_t12 + K_t21, K_t22 / step factor
    coupling: np.ndarray       # (P, K, 2) m/s per N s: tangential velocity per normal impulse
    allowance: np.ndarray      # (P, K) m/s
    mu: np.ndarray             # (P, K)
    normal: np.ndarray         # (P, K) N s, accumulated
    tangent: np.ndarray        # (P, K, 2) N s, accumulated


@dataclass
class ContactRows:
    """Per-contact constants of one step, rows sorted by colour then pair (see ``order``).

    Every per-contact array is in that order; ``order[k]`` is the index of
    row k in the caller's contact arrays.
    """

    order: np.ndarray          # (M,) int, caller index of each row
    batches: list[Batch]       # one per colour
    pair: np.ndarray           # (M, 2) int, body indices A, B
    basis: np.ndarray          # (M, 3, 3) rows n, t1, t2, unit, world
    jacobian: np.ndarray       # (M, 3, 12) relative velocity of each row = J . [vA wA vB wB]
    response: np.ndarray       # (M, 12, 3) velocity change per unit row impulse, M^-1 J^T
    normal_mass: np.ndarray    # (M,) kg, 1 / (k J_n M^-1 J_n^T) (mass split over k rows)
    tangent_block: np.ndarray  # (M, 2, 2) 1/kg, tangential Delassus block (split)
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
    """Accumulated impulses of the rows (N s), in row order."""

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


def colour_pairs(pair: np.ndarray, movable: np.ndarray, max_colours: int = MAX_COLOURS,
                 key: np.ndarray | None = None) -> np.ndarray:
    """Colour per contact: no movable body in two different groups of one colour.

    A group is a pair, or the rows sharing ``key`` (e.g. chunks of a big
    manifold). Greedy over the groups with one bitmask of used colours per
    body; a group that finds no free colour below ``max_colours`` shares one
    (mass splitting keeps such a colour correct, only less Gauss-Seidel-like).
    """
    count = movable.shape[0]
    if key is None:
        key = pair[:, 0] * count + pair[:, 1]
    _, first, which = np.unique(key, return_index=True, return_inverse=True)
    masks = [0] * count
    move = movable.tolist()
    colours = []
    for a, b in pair[first].tolist():
        used = (masks[a] if move[a] else 0) | (masks[b] if move[b] else 0)
        bit = ~used & (used + 1)            # lowest free colour
        colour = bit.bit_length() - 1
        if colour >= max_colours:
            colour = len(colours) % max_colours
            bit = 1 << colour
        colours.append(colour)
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
            max_colours: int = MAX_COLOURS) -> ContactRows:
    """Constraint rows of M contacts.

    pair (M, 2) body indices; normal (M, 3) unit, A to B; r_a, r_b (M, 3) m,
    contact point minus each centre of mass; inv_mass (N,) 1/kg and
    inv_inertia (N, 3, 3) world frame, both zero for immovable bodies;
    velocity (N, 6) pre-solve; allowance (M,) m/s approach allowed without
    impulse; restitution (e on A, e on B); friction (mu_static, mu_kinetic);
    threshold m/s (restitution above it); a contact whose tangential speed is
    below ``sticking_speed`` (m/s) may stick: that speed is measured with
    ``sticking_velocity`` (N, 6), e.g. the velocities before this step's
    external forces, default ``velocity``. ``max_colours`` = 1 is Jacobi
    with mass splitting over all rows.
    """
    pair = np.asarray(pair, np.int64).reshape(-1, 2)
    count = inv_mass.shape[0]
    movable = inv_mass > 0.0
    key = _chunk_keys(pair[:, 0] * count + pair[:, 1])
    colour = _merge_small(colour_pairs(pair, movable, max_colours, key), key)
    order = np.lexsort((key, colour))
    pair, normal, r_a, r_b = pair[order], normal[order], r_a[order], r_b[order]
    colour, key = colour[order], key[order]
    edges = np.flatnonzero(np.diff(colour)) + 1
    spans = list(zip(np.r_[0, edges].tolist(), np.r_[edges, colour.shape[0]].tolist()))
    # mass splitting across pairs: pairs of the colour that act on each body (k), per side
    share = np.ones((pair.shape[0], 2))
    for lo, hi in spans:
        first = np.r_[True, key[lo + 1:hi] != key[lo:hi - 1]]
        pairs_of = np.bincount(pair[lo:hi][first].ravel(), minlength=count)
        share[lo:hi] = pairs_of[pair[lo:hi]]

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
    # Delassus block of each row, each body's mass split over the rows of the colour on it
    delassus = (jacobian[:, :, :6] @ response[:, :6, :]) * share[:, 0, None, None] \
        + (jacobian[:, :, 6:] @ response[:, 6:, :]) * share[:, 1, None, None]
    k_n = delassus[:, 0, 0]
    normal_mass = np.where(k_n > _TINY, 1.0 / np.where(k_n > _TINY, k_n, 1.0), 0.0)
    relative = _row_velocity(jacobian, velocity, pair)
    slow = relative if sticking_velocity is None else \
        _row_velocity(jacobian, sticking_velocity, pair)
    approach = relative[:, 0]
    sticking = np.hypot(slow[:, 1], slow[:, 2]) < sticking_speed
    rows = ContactRows(
        order=order, batches=[], pair=pair, basis=basis, jacobian=jacobian,
        response=response, normal_mass=normal_mass, tangent_block=delassus[:, 1:, 1:],
        coupling=delassus[:, 1:, 0], approach=approach,
        allowance=np.asarray(allowance, float)[order],
        bounce=approach < -threshold,
        restitution_a=np.asarray(restitution[0], float)[order],
        restitution_b=np.asarray(restitution[1], float)[order],
        mu=np.where(sticking, np.asarray(friction[0], float)[order],
                    np.asarray(friction[1], float)[order]),
        sticking=sticking)
    padded = {name: _padded(getattr(rows, name)) for name in (
        'jacobian', 'response', 'allowance', 'mu', 'tangent_block', 'coupling')}
    rows.batches = _batches(rows, padded, key, colour, movable, share)
    return rows


def _merge_small(colour: np.ndarray, key: np.ndarray) -> np.ndarray:
    """Colours past the first KEEP_COLOURS with fewer than MIN_PAIRS groups join the
    previous colour (mass splitting), so a small stack keeps its Gauss-Seidel order.

    A numpy call costs the same for 2 or 200 pairs: tiny colours are not
    worth their own pass.
    """
    if colour.size == 0:
        return colour
    _, first = np.unique(key, return_index=True)
    groups = np.bincount(colour[first])
    target = np.arange(groups.shape[0])
    for c in range(KEEP_COLOURS, groups.shape[0]):
        if groups[c] < MIN_PAIRS:
            target[c] = target[c - 1]
    return target[colour]


def _chunk_keys(pair_key: np.ndarray) -> np.ndarray:
    """Group key per row: its pair, cut into chunks of at most MAX_POINTS rows.

    Chunks of one pair share bodies, so they get different colours
    (Gauss-Seidel between them) and the padded width K stays small.
    """
    order = np.argsort(pair_key, kind='stable')
    ordered = pair_key[order]
    index = np.arange(ordered.shape[0])
    start = np.r_[True, ordered[1:] != ordered[:-1]]
    rank = np.empty_like(index)
    rank[order] = index - np.maximum.accumulate(np.where(start, index, 0))
    return pair_key * 64 + np.minimum(rank // MAX_POINTS, 63)


def _padded(array: np.ndarray) -> np.ndarray:
    """The array with one zero row appended (the padding row, index M)."""
    return np.concatenate((array, np.zeros((1,) + array.shape[1:], array.dtype)))


def _batches(rows: ContactRows, padded: dict[str, np.ndarray], key: np.ndarray,
             colour: np.ndarray, movable: np.ndarray, share: np.ndarray) -> list[Batch]:
    """The padded (P, K) layout of all pairs, cut into one Batch (views) per colour.

    The K points of a pair are solved together (Jacobi), each row's step
    scaled by ``_step_factor`` of the pair's normal Delassus matrix (by the
    Gershgorin bound for the tangent rows), so the joint step never overshoots.
    """
    total = rows.count
    starts = np.r_[0, np.flatnonzero(np.diff(key)) + 1]        # rows sorted by colour, pair
    sizes = np.diff(np.r_[starts, total])
    p, k = starts.shape[0], int(sizes.max())
    slot = np.full((p, k), total, np.int64)
    slot[np.arange(k)[None, :] < sizes[:, None]] = np.arange(total)
    pairs = rows.pair[starts]
    jacobian = padded['jacobian'][slot]                        # (P, K, 3, 12)
    response = padded['response'][slot]                        # (P, K, 12, 3)
    side = np.repeat(share[starts], 6, axis=1)                 # (P, 12) split factors
    flat_response = np.ascontiguousarray(response.transpose(0, 2, 1, 3).reshape(p, 12, k * 3))
    normal_jacobian = np.ascontiguousarray(jacobian[:, :, 0, :])              # (P, K, 12)
    normal_response = np.ascontiguousarray(response[:, :, :, 0].transpose(0, 2, 1))
    normal = normal_jacobian @ (normal_response * side[:, :, None])            # (P, K, K)
    tangent = jacobian[:, :, 1:, :].reshape(p, 2 * k, 12) @ (
        response[:, :, :, 1:].transpose(0, 2, 1, 3).reshape(p, 12, 2 * k) * side[:, :, None])
    omega_n, omega_t = _step_factor(normal), _gershgorin(tangent)
    diag = np.einsum('pkk->pk', normal)
    normal_mass = np.where(diag > _TINY, omega_n[:, None] / np.where(diag > _TINY, diag, 1.0),
                           0.0)
    block = padded['tangent_block'][slot] / omega_t[:, None, None, None]       # (P, K, 2, 2)
    quad = np.stack((block[..., 0, 0], block[..., 0, 1] + block[..., 1, 0], block[..., 1, 1]))
    coupling = padded['coupling'][slot]
    jacobian = jacobian.reshape(p, k * 3, 12)
    allowance, mu = padded['allowance'][slot], padded['mu'][slot]
    pair_colour = colour[starts]
    cuts = np.r_[0, np.flatnonzero(np.diff(pair_colour)) + 1, p].tolist()
    batches = []
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        bodies = pairs[lo:hi][movable[pairs[lo:hi]]]
        batches.append(Batch(
            pairs=pairs[lo:hi], slot=slot[lo:hi],
            unique=bool(np.unique(bodies).shape[0] == bodies.shape[0]),
            jacobian=jacobian[lo:hi], response=flat_response[lo:hi],
            normal_jacobian=normal_jacobian[lo:hi], normal_response=normal_response[lo:hi],
            normal_mass=normal_mass[lo:hi], tangent_quad=quad[:, lo:hi],
            coupling=coupling[lo:hi], allowance=allowance[lo:hi], mu=mu[lo:hi],
            normal=np.zeros((hi - lo, k)), tangent=np.zeros((hi - lo, k, 2))))
    return batches


def _step_factor(matrix: np.ndarray) -> np.ndarray:
    """Jacobi step factor (P,) in (0, 1]: 1 / largest eigenvalue of D^-1/2 A D^-1/2.

    With it the joint Jacobi step of a pair's rows never overshoots (A is the
    pair's Delassus matrix, D its diagonal; padding rows have A_ii = 0).
    """
    diag = np.einsum('pkk->pk', matrix)
    inv_sqrt = np.where(diag > _TINY, 1.0 / np.sqrt(np.where(diag > _TINY, diag, 1.0)), 0.0)
    scaled = matrix * inv_sqrt[:, :, None] * inv_sqrt[:, None, :]
    largest = np.linalg.eigvalsh(0.5 * (scaled + scaled.transpose(0, 2, 1)))[:, -1]
    return 1.0 / np.maximum(largest, 1.0)


def _gershgorin(matrix: np.ndarray) -> np.ndarray:
    """A cheaper, smaller safe step factor (P,): 1 / max_i sum_j |A_ij| / A_ii."""
    diag = np.einsum('pkk->pk', matrix)
    ratio = np.abs(matrix).sum(axis=2) / np.where(diag > _TINY, diag, np.inf)
    return 1.0 / np.maximum(ratio.max(axis=1), 1.0)


def _row_velocity(jacobian: np.ndarray, velocity: np.ndarray, pair: np.ndarray) -> np.ndarray:
    """Relative velocity (M, 3) along n, t1, t2 (m/s)."""
    stacked = velocity[pair].reshape(-1, 12)
    return np.einsum('mdj,mj->md', jacobian, stacked)


def _scatter(batch: Batch, velocity: np.ndarray, gathered: np.ndarray,
             change: np.ndarray) -> None:
    """Add per-pair velocity changes (P, 12) to the bodies of a colour."""
    if batch.unique:   # movable bodies once each; immovable ones get a zero change
        velocity[batch.pairs] = (gathered + change).reshape(-1, 2, 6)
    else:
        np.add.at(velocity, batch.pairs.ravel(), change.reshape(-1, 6))


def warm_start(rows: ContactRows, impulses: Impulses, velocity: np.ndarray) -> None:
    """Apply last step's accumulated impulses (already projected on this step's rows)."""
    if rows.count:
        delta = np.concatenate((impulses.normal[:, None], impulses.tangent), axis=1)
        change = np.einsum('mjd,md->mj', rows.response, delta)
        np.add.at(velocity, rows.pair.ravel(), change.reshape(-1, 6))


def solve_velocities(rows: ContactRows, impulses: Impulses, velocity: np.ndarray,
                     iterations: int) -> int:
    """Sequential impulses: normal clamped >= 0, friction clamped to the circular cone.

    Stops early once a whole sweep changes no impulse by more than
    CONVERGED times the largest normal impulse; returns the sweeps done.
    """
    normal, tangent = _padded(impulses.normal), _padded(impulses.tangent)
    for batch in rows.batches:
        batch.normal, batch.tangent = normal[batch.slot], tangent[batch.slot]
    done = 0
    while done < iterations:
        done += 1
        change, largest = 0.0, 0.0
        for batch in rows.batches:
            step, top = _solve_batch(batch, velocity)
            change, largest = max(change, step), max(largest, top)
        if change <= CONVERGED * largest:
            break
    for batch in rows.batches:
        valid = batch.slot < rows.count
        impulses.normal[batch.slot[valid]] = batch.normal[valid]
        impulses.tangent[batch.slot[valid]] = batch.tangent[valid]
    return done


def _solve_batch(b: Batch, velocity: np.ndarray) -> tuple[float, float]:
    """One Jacobi step of a colour; returns (largest impulse change, largest normal impulse)."""
    gathered = velocity[b.pairs].reshape(-1, 12)
    rel = (b.jacobian @ gathered[:, :, None]).reshape(b.slot.shape + (3,))
    # normal: approach no faster than the speculative allowance, accumulated impulse >= 0
    new_n = np.maximum(b.normal - b.normal_mass * (rel[:, :, 0] + b.allowance), 0.0)
    d_n = new_n - b.normal
    # friction: oppose the tangential slip left after the normal change (the classic
    # tangent, v_t / |v_t|), as much as stops it along that direction, within mu * j_n
    v_t = rel[:, :, 1:] + b.coupling * d_n[:, :, None]
    x, y = v_t[:, :, 0], v_t[:, :, 1]
    speed2 = x * x + y * y
    quad = b.tangent_quad
    stiffness = quad[0] * x * x + quad[1] * x * y + quad[2] * y * y
    slip = speed2 / np.maximum(stiffness, _TINY * speed2 + 1e-300)   # 0 when v_t = 0
    trial = b.tangent - v_t * slip[:, :, None]
    size = np.hypot(trial[:, :, 0], trial[:, :, 1])
    scale = np.minimum(1.0, b.mu * new_n / np.maximum(size, 1e-300))
    new_t = trial * scale[:, :, None]
    delta = np.concatenate((d_n[:, :, None], new_t - b.tangent), axis=2)
    b.normal, b.tangent = new_n, new_t
    change = (b.response @ delta.reshape(delta.shape[0], -1, 1))[:, :, 0]
    _scatter(b, velocity, gathered, change)
    return float(np.abs(delta).max()), float(new_n.max())


def apply_restitution(rows: ContactRows, impulses: Impulses, velocity: np.ndarray) -> None:
    """One pass: bouncing contacts leave at -e times their pre-solve approach speed.

    Only contacts that approached faster than the threshold and carry a
    normal impulse bounce; A's and B's extra impulses use their own e (equal
    unless the per_object rule is chosen), each keeping the total >= 0.
    """
    total, bounce = _padded(impulses.normal), _padded(rows.bounce)
    approach = _padded(rows.approach)
    e_a, e_b = _padded(rows.restitution_a), _padded(rows.restitution_b)
    extra = np.zeros((rows.count + 1, 2))
    for b in rows.batches:
        slot = b.slot
        active = bounce[slot] & (total[slot] > 0.0)
        if not active.any():
            continue
        gathered = velocity[b.pairs].reshape(-1, 12)
        v_n = (b.normal_jacobian @ gathered[:, :, None])[:, :, 0]
        pre, mass = approach[slot], b.normal_mass
        d_a = np.where(active, np.maximum(-mass * (v_n + e_a[slot] * pre), -total[slot]), 0.0)
        d_b = np.where(active, np.maximum(-mass * (v_n + e_b[slot] * pre), -total[slot]), 0.0)
        extra[slot] = np.stack((d_a, d_b), axis=2)
        change = np.concatenate(((b.normal_response[:, :6] @ d_a[:, :, None])[:, :, 0],
                                 (b.normal_response[:, 6:] @ d_b[:, :, None])[:, :, 0]), axis=1)
        _scatter(b, velocity, gathered, change)
    impulses.restitution[:] = extra[:-1]


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
    push = _padded(push)
    accumulated = [np.zeros(b.slot.shape) for b in rows.batches]
    for _ in range(iterations):
        for b, old in zip(rows.batches, accumulated):
            gathered = pseudo[b.pairs].reshape(-1, 12)
            v_n = (b.normal_jacobian @ gathered[:, :, None])[:, :, 0]
            new = np.maximum(old + b.normal_mass * (push[b.slot] - v_n), 0.0)
            change = (b.normal_response @ (new - old)[:, :, None])[:, :, 0]
            old[...] = new
            _scatter(b, pseudo, gathered, change)
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
