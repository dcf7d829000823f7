"""Contact response: the documented impulse, generalised to many contacts by sequential impulses.

For one contact this is exactly formulas.md section 3: with ``r × n`` written
``rn`` and the scalar triple product ``((I⁻¹ rn) × r)·n = rn·(I⁻¹ rn)``,

    j = -(1 + e) (v_rel·n) / (1/m_A + 1/m_B + rn_A·I_A⁻¹ rn_A + rn_B·I_B⁻¹ rn_B)

For several contacts, each contact ``i`` gets a target normal velocity
``-e (v_rel·n)`` from its approach speed *before* the solve, and the solver
sweeps the contacts, each time applying the impulse that reaches its target,
with the accumulated impulse clamped to ``>= 0`` (contacts push, never pull;
Catto's sequential impulses). A single contact converges in one sweep to the
documented ``j``.

Vectorization: contacts are coloured so that no two contacts of one colour
share a dynamic body; one colour is then one NumPy update (Gauss-Seidel
between colours, exact within a colour because the contacts are independent).
Body velocities live in one array ``body_twist (n + 1, 6)``: rows are bodies,
columns ``[v (3), ω (3)]`` world frame, and the extra last row is the zero
twist of every fixed body, so contacts with the ground never block a colour.

Each contact row is a 12-vector Jacobian ``J = [-n, -rn_A, n, rn_B]`` over
``[twist_A, twist_B]``: ``J · twist = (v_PB - v_PA)·n``; ``M⁻¹Jᵀ`` holds the
matching velocity change per unit impulse.

Friction (not in the documented formulas; on when a pair has μ > 0) is isotropic Coulomb
at every contact, whatever its tangent basis: the two tangent rows of a contact are solved
as one 2x2 block ``K = J_t M⁻¹ J_tᵀ`` (``_TangentBlock``). Each update is either the
sticking impulse ``λ - K⁻¹ v``, exact in one update, when it lies in the disc ``μ λ_n``, or
else the current impulse stepped against the contact's current slip ``v`` with one scalar
mass and cut to the disc, so that at convergence the friction impulse has magnitude
``μ λ_n`` and opposes the final slip (``_friction_update`` derives the rule).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from mini_engine.contacts import Contacts, read_only
from mini_engine.model import Model
from mini_engine.rotation import apply, cross, einsum, last_axis_sum, norm
from mini_engine.settings import Settings
from mini_engine.workspace import Workspace, workspace

RESTITUTION_MIX: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "max": np.maximum,
    "min": np.minimum,
    "mean": lambda a, b: 0.5 * (a + b),
    "product": np.multiply,
}
"""Pair restitution from the two bodies' values (``Settings.restitution_mix``)."""

FRICTION_MIX: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "geometric_mean": lambda a, b: np.sqrt(a * b),
    "min": np.minimum,
    "max": np.maximum,
    "product": np.multiply,
}
"""Pair friction coefficient from the two bodies' values (``Settings.friction_mix``)."""


COLOUR_SEED = 20151
"""Seed of the contact priority permutation used by the colouring (any fixed value works;
fixed so that the same contacts always get the same colours)."""

TINY_IMPULSE = 1e-300
"""N·s. Guards the friction-disc projection against 0/0 when the sliding step is zero
(any positive value far below a real impulse works; 1e-300 is near the smallest normal double)."""

WARM_START_MATCH_FRACTION = 0.1
"""A contact inherits last step's impulse from a contact of the same pair at most this
fraction of the pair's smaller bounding radius away (resting contacts move far less;
the four corners of a 10 cm box face are 14 times further apart)."""

COLOUR_PRIORITY_CACHE = 64
"""Contact counts whose priority permutation is kept (a settling scene's count wanders
within a few dozen values; 64 arrays of a few thousand ints are a few MB at most)."""

COLOUR_ROUNDS = 3
"""Claim rounds per colour. Measured on a 1000-sphere pile (3,700 contacts): 3 rounds give
11 colours in 1.0 ms; unlimited rounds 12 colours in 1.1 ms; 1 round 23 colours."""


class ContactReport(NamedTuple):
    """What happened at every contact during one step (c contacts).

    Attributes:
        contacts: the detected contacts (bodies, point, normal A→B, depth).
        restitution: (c,) the pair's e used.
        normal_velocity_before: (c,) m/s, ``(v_PB - v_PA)·n`` after the applied forces and
            before any impulse; negative while approaching.
        normal_velocity_after: (c,) m/s, the same after the solve.
        normal_impulse: (c,) N·s, accumulated impulse along n on B (and -n on A), >= 0.
        friction_impulse: (c, 3) N·s, world frame, accumulated tangential impulse on B.
        iterations: solver sweeps used.
    """

    contacts: Contacts
    restitution: np.ndarray
    normal_velocity_before: np.ndarray
    normal_velocity_after: np.ndarray
    normal_impulse: np.ndarray
    friction_impulse: np.ndarray
    iterations: int

    @staticmethod
    def empty() -> ContactReport:
        """The report of a step without contacts: one shared read-only instance."""
        return NO_CONTACT_REPORT


NO_CONTACT_REPORT = ContactReport(
    Contacts.empty(),
    read_only(np.zeros(0)),
    read_only(np.zeros(0)),
    read_only(np.zeros(0)),
    read_only(np.zeros(0)),
    read_only(np.zeros((0, 3))),
    0,
)
"""``ContactReport.empty()``."""


class _Rows(NamedTuple):
    """Solver rows of one constraint direction, ordered by colour (c rows)."""

    jacobian: np.ndarray  # (c, 12) [-d, -r_A×d, d, r_B×d]
    response: np.ndarray  # (c, 12) M⁻¹Jᵀ: twist change per unit impulse
    mass: np.ndarray  # (c,) effective mass 1/(J M⁻¹ Jᵀ), kg
    inverse_mass: np.ndarray  # (c,) J M⁻¹ Jᵀ, 1/kg: velocity change per unit impulse


class _TangentBlock(NamedTuple):
    """The 2x2 tangent block of each contact's two friction rows (c contacts).

    With ``J_t (2, 12)`` the contact's two tangent rows, ``K = J_t M⁻¹ J_tᵀ`` (2, 2), 1/kg, is
    the change of the contact's slip ``(v_t1, v_t2)`` m/s per unit tangent impulse N·s. Its
    off-diagonal term is ``(r × t1)·I⁻¹(r × t2)`` summed over both bodies (``t1·t2 = 0``):
    zero for a sphere (its arm along the normal, its inertia round) but not for a box
    corner: ``-ab/I_zz`` for a level box's corner at ``(a, b, -h)`` from its centre with
    ``t1, t2`` along y and -x, whose diagonal terms ``1/m + h²/I_xx + a²/I_zz`` and
    ``1/m + h²/I_yy + b²/I_zz`` also differ unless the box is square.

    Attributes:
        sticking_mass: (c, 2, 2) kg, ``K⁻¹``: ``-K⁻¹ v`` is the impulse that cancels a slip
            ``v (2,)`` in one update.
        step_mass: (c,) kg, ``2 / tr K``, the scalar mass of the sliding update
            (``_friction_update``); ``1/k`` when ``K = k·1``.
    """

    sticking_mass: np.ndarray
    step_mass: np.ndarray


@dataclass(frozen=True, eq=False)
class _ContactGraph:
    """What the solver derives from the contacts' bodies alone (c contacts, in colour order).

    It is the same for every step whose contacts join the same bodies in the same order (a
    settled pile, a body at rest), so ``_contact_graph`` builds it once for them; every
    array is read-only.

    Attributes:
        key: ``(c, body_a bytes, body_b bytes, restitution rule, friction rule)`` of the
            detected contacts it was built for.
        order: (c,) int, the stable sort of the detected contacts by colour, or None when
            that is the identity (one contact, or already in colour order).
        batches: the slices of ``[0, c)`` holding each colour.
        body_a, body_b: (c,) int, the bodies of each contact.
        pair_key: (c,) int, ``body_a * n + body_b`` (n bodies), one value per body pair.
        pair_rows: (c, 2) int, the twist rows of A and B (``Workspace.body_row``).
        twist_index: (c, 12) int, ``_twist_index(pair_rows)``.
        inv_mass_a, inv_mass_b: (c,) 1/kg, of A and B.
        restitution: (c,) and friction: (c,), ``pair_values``.
        negative_restitution: (c,), ``-restitution`` (``_normal_targets``).
        use_friction: some contact has μ > 0 (otherwise no tangent rows are built).
        match_distance_sq: (c,) m², the squared warm-start match distance
            (``WARM_START_MATCH_FRACTION`` of the pair's smaller bounding radius).
        no_friction_impulse: (c, 3) zeros, the friction impulses reported without friction.
        gathered: one colour, no friction, and no twist row shared by two contacts (a single
            contact): every gather of the contacts' twists would read back exactly what the
            last update stored, so the solve keeps them gathered (``_solve_gathered``).
    """

    key: tuple
    order: np.ndarray | None
    batches: list[slice]
    body_a: np.ndarray
    body_b: np.ndarray
    pair_key: np.ndarray
    pair_rows: np.ndarray
    twist_index: np.ndarray
    inv_mass_a: np.ndarray
    inv_mass_b: np.ndarray
    restitution: np.ndarray
    negative_restitution: np.ndarray
    friction: np.ndarray
    use_friction: bool
    match_distance_sq: np.ndarray
    no_friction_impulse: np.ndarray
    gathered: bool

    @functools.cached_property
    def unique_pairs(self) -> bool:
        """No body pair has two contacts (needed only when the graph is met again: a sort)."""
        return np.unique(self.pair_key).size == self.pair_key.size


def pair_values(
    model: Model, contacts: Contacts, settings: Settings
) -> tuple[np.ndarray, np.ndarray]:
    """Restitution (c,) and friction coefficient (c,) of each contact's body pair.

    The mixing rules of ``settings`` apply unless the model overrides the pair.
    """
    a, b = contacts.body_a, contacts.body_b
    restitution = RESTITUTION_MIX[settings.restitution_mix](
        model.body_restitution[a], model.body_restitution[b]
    )
    friction = FRICTION_MIX[settings.friction_mix](model.body_friction[a], model.body_friction[b])
    if model.pair_body_a.size:
        n = model.n_bodies
        override_key = np.minimum(model.pair_body_a, model.pair_body_b) * n + np.maximum(
            model.pair_body_a, model.pair_body_b
        )
        contact_key = np.minimum(a, b) * n + np.maximum(a, b)
        order = np.argsort(override_key, kind="stable")
        slot = np.clip(np.searchsorted(override_key[order], contact_key), 0, order.size - 1)
        hit = override_key[order][slot] == contact_key
        chosen = order[slot]
        pair_e, pair_mu = model.pair_restitution[chosen], model.pair_friction[chosen]
        restitution = np.where(hit & ~np.isnan(pair_e), pair_e, restitution)
        friction = np.where(hit & ~np.isnan(pair_mu), pair_mu, friction)
    return restitution, friction


@functools.lru_cache(maxsize=COLOUR_PRIORITY_CACHE)
def _lowest_priority_first(count: int) -> np.ndarray:
    """(count,) int, the contacts from the lowest to the highest colouring priority: the
    seeded permutation reversed. The same for every step with ``count`` contacts, so it
    is drawn once per count (read-only)."""
    order = np.random.default_rng(COLOUR_SEED).permutation(count)[::-1].copy()
    order.flags.writeable = False
    return order


def colour_contacts(row_a: np.ndarray, row_b: np.ndarray, static_row: int) -> np.ndarray:
    """Colour (c,) int of each contact; no two contacts of one colour share a dynamic body.

    Luby-style rounds, all vectorized. Each contact has a fixed pseudo-random priority
    (a seeded permutation, so the result is deterministic). In a round every body claims
    its highest-priority candidate contact; a contact claimed by both its bodies joins the
    colour, its bodies are marked used, and candidates touching no used body try again,
    up to ``COLOUR_ROUNDS`` times; then the next colour starts. Random priorities matter:
    contacts come out of the broad phase in spatial order, and index priorities then form
    long chains where only a few contacts win each round. The static row never blocks:
    each contact's fixed side gets a private row of its own for the colouring.
    """
    count = row_a.size
    private = static_row + np.arange(count)
    pair_rows = np.stack(
        [
            np.where(row_a == static_row, private, row_a),
            np.where(row_b == static_row, private, row_b),
        ],
        axis=1,
    )
    colour = np.full(count, -1, dtype=np.int64)
    claim = np.empty(static_row + count, dtype=np.int64)
    remaining = _lowest_priority_first(count).copy()  # the last write of a claim wins
    current = 0
    while remaining.size:
        candidates = remaining
        for _ in range(COLOUR_ROUNDS):
            if not candidates.size:
                break
            rows = pair_rows.take(candidates, axis=0)
            claim[rows.ravel()] = np.repeat(candidates, 2)
            claimant = claim[rows]  # (m, 2): the candidate each of its rows went to
            wins = (claimant[:, 0] == candidates) & (claimant[:, 1] == candidates)
            colour[candidates[wins]] = current  # never none: the top priority always wins
            # every row of a candidate went to a candidate of this round, so the rows now
            # used by the colour are those whose claimant won; the others try again
            taken = colour[claimant] == current
            candidates = candidates[~(taken[:, 0] | taken[:, 1])]
        remaining = remaining[colour[remaining] < 0]
        current += 1
    return colour


def _contact_graph(
    model: Model, work: Workspace, contacts: Contacts, settings: Settings
) -> _ContactGraph:
    """The contact graph of ``contacts``: the last step's while the contacts join the same
    bodies in the same order (kept in the model workspace's ``colour_cache``), else built
    afresh; either way the same values."""
    cache = work.colour_cache
    key = (
        contacts.count,
        contacts.body_a.tobytes(),
        contacts.body_b.tobytes(),
        settings.restitution_mix,
        settings.friction_mix,
    )
    last = cache.get("graph")
    if last is not None and last.key == key:
        return last
    graph = _build_contact_graph(model, contacts, settings, key)
    cache.update(graph=graph, batches=graph.batches)
    return graph


def _build_contact_graph(
    model: Model, contacts: Contacts, settings: Settings, key: tuple
) -> _ContactGraph:
    """Colour the contacts, order them by colour and gather what depends on their bodies."""
    n = model.n_bodies
    body_row = workspace(model).body_row
    order, batches = _colour_batches(
        body_row[contacts.body_a], body_row[contacts.body_b], static_row=n
    )
    restitution, friction = pair_values(model, contacts, settings)
    side_body = np.stack([contacts.body_a, contacts.body_b], axis=1)
    if order is not None:
        side_body, restitution, friction = side_body[order], restitution[order], friction[order]
    a, b = side_body[:, 0].copy(), side_body[:, 1].copy()
    pair_rows = body_row[side_body]
    radius = np.minimum(model.body_bound_radius[a], model.body_bound_radius[b])
    use_friction = bool(np.any(friction > 0.0))
    graph = _ContactGraph(
        key=key,
        order=order,
        batches=batches,
        body_a=a,
        body_b=b,
        pair_key=a * n + b,
        pair_rows=pair_rows,
        twist_index=_twist_index(pair_rows),
        inv_mass_a=model.body_inv_mass[a],
        inv_mass_b=model.body_inv_mass[b],
        restitution=restitution,
        negative_restitution=-restitution,
        friction=friction,
        use_friction=use_friction,
        match_distance_sq=(WARM_START_MATCH_FRACTION * radius) ** 2,
        no_friction_impulse=np.zeros((a.size, 3)),
        gathered=len(batches) == 1
        and not use_friction
        and np.unique(pair_rows).size == pair_rows.size,
    )
    for value in vars(graph).values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return graph


def _colour_batches(
    row_a: np.ndarray, row_b: np.ndarray, static_row: int
) -> tuple[np.ndarray | None, list[slice]]:
    """The colour order of the contacts and one slice per colour of the reordered contacts.

    Returns ``(order, batches)``: ``order (c,)`` int, the stable sort of the contacts by
    colour (``colour_contacts``), or None when that is the identity (one contact, or already
    in colour order); ``batches`` the slices of ``[0, c)`` holding each colour.
    """
    count = row_a.size
    if count == 1:
        return None, [slice(0, 1)]
    colour = colour_contacts(row_a, row_b, static_row)
    order = np.argsort(colour, kind="stable")
    bounds = np.searchsorted(colour[order], np.arange(colour.max() + 2))
    batches = [slice(bounds[k], bounds[k + 1]) for k in range(bounds.size - 1)]
    if np.array_equal(order, np.arange(count)):
        order = None
    return order, batches


def _twist_index(pair_rows: np.ndarray) -> np.ndarray:
    """(c, 12) int, flat indices into a ``(rows, 6)`` twist array of ``[twist_A, twist_B]``
    of each contact: the sweeps scatter through them (a flat fancy store is about 2.4x
    faster than a row store with a (c, 2) index; the values written are the same)."""
    return (pair_rows[:, :, None] * 6 + np.arange(6)).reshape(-1, 12)


def _in_colour_order(contacts: Contacts, graph: _ContactGraph) -> Contacts:
    """``contacts`` reordered by colour (``graph.order``), with the graph's body arrays."""
    if graph.order is None:
        return Contacts(graph.body_a, graph.body_b, contacts.point, contacts.normal, contacts.depth)
    order = graph.order
    return Contacts(
        graph.body_a,
        graph.body_b,
        contacts.point.take(order, axis=0),
        contacts.normal.take(order, axis=0),
        contacts.depth.take(order),
    )


def _rows(direction, arm_a, arm_b, inv_mass_a, inv_mass_b, inv_inertia_a, inv_inertia_b) -> _Rows:
    """Jacobian, response and effective mass of constraint rows along ``direction (c, 3)``."""
    rd_a, rd_b = cross(arm_a, direction), cross(arm_b, direction)
    w_a, w_b = apply(inv_inertia_a, rd_a), apply(inv_inertia_b, rd_b)
    jacobian = np.concatenate([-direction, -rd_a, direction, rd_b], axis=1)
    response = np.concatenate(
        [-inv_mass_a[:, None] * direction, -w_a, inv_mass_b[:, None] * direction, w_b], axis=1
    )
    inverse_mass = inv_mass_a + inv_mass_b + last_axis_sum(rd_a * w_a) + last_axis_sum(rd_b * w_b)
    return _Rows(jacobian, response, 1.0 / inverse_mass, inverse_mass)


def _kept_rows(
    kept: dict, graph: _ContactGraph, direction, arm_a, arm_b, inv_inertia_a, inv_inertia_b
) -> _Rows:
    """``_rows`` along ``direction (c, 3)`` with the arms ``arm_a, arm_b (c, 3)`` m and the
    world inverse inertias ``inv_inertia_a, inv_inertia_b (c, 3, 3)`` of A and B.

    Rows are a function of the graph and these arrays alone: while all are bit for bit
    those of the last call (a body resting still on the ground), the last rows, which
    ``kept`` holds (the workspace's, per direction), are returned.
    """
    inputs = _same_row_inputs(
        kept.get("inputs"), graph, direction, (arm_a, arm_b, inv_inertia_a, inv_inertia_b)
    )
    if inputs is None:
        return kept["rows"]
    rows = _rows(
        direction,
        arm_a,
        arm_b,
        graph.inv_mass_a,
        graph.inv_mass_b,
        inv_inertia_a,
        inv_inertia_b,
    )
    kept.update(inputs=inputs, rows=rows)
    return rows


def _kept(work: Workspace, direction: str) -> dict:
    """What the workspace keeps of the rows along ``direction`` (``_kept_rows``)."""
    return work.solver_rows.setdefault(direction, {})


def _same_row_inputs(
    last: tuple | None, graph: _ContactGraph, direction: np.ndarray, others: tuple
) -> tuple | None:
    """None when ``graph`` is the last call's and ``direction`` and the arrays ``others``
    have its bytes (``last``), else the record of these inputs for the next call.

    The direction is compared first: the other arrays are copied to bytes only once it
    has repeated, so a scene whose contacts move pays for one small copy per call."""
    direction_bytes = direction.tobytes()
    if last is None or last[0] is not graph or last[1] != direction_bytes:
        return (graph, direction_bytes, None)
    inputs = (graph, direction_bytes, tuple(array.tobytes() for array in others))
    return None if inputs[2] == last[2] else inputs


def _tangents(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (c, 3) completing ``normal (c, 3)`` to a right-handed basis."""
    helper = np.where(
        (np.abs(normal[:, 0]) < 0.57735)[:, None],
        np.array([1.0, 0.0, 0.0]),
        np.array([0.0, 1.0, 0.0]),
    )
    t1 = cross(normal, helper)
    t1 /= norm(t1, keepdims=True)
    return t1, cross(normal, t1)


def _tangent_rows(
    work: Workspace, graph: _ContactGraph, normal: np.ndarray, geometry: tuple
) -> tuple[np.ndarray, np.ndarray, _Rows, _TangentBlock]:
    """The tangents ``t1, t2 (c, 3)`` of ``normal (c, 3)``, the two tangent rows of every
    contact (jacobian and response (c, 2, 12), mass and inverse mass (c, 2)) and their
    ``_TangentBlock``; ``geometry`` is ``(arm_a, arm_b, inv_inertia_a, inv_inertia_b)``.

    Each tangent's rows are ``_kept_rows``; while both are the very objects of the last call
    (their inputs bit for bit the same), so are the stacked rows and the block, which the
    workspace keeps next to them."""
    t1, t2 = _tangents(normal)
    first = _kept_rows(_kept(work, "first tangent"), graph, t1, *geometry)
    second = _kept_rows(_kept(work, "second tangent"), graph, t2, *geometry)
    kept = _kept(work, "tangent block")
    if kept.get("first") is first and kept.get("second") is second:
        return t1, t2, kept["rows"], kept["block"]
    rows = _Rows(*(np.stack(pair, axis=1) for pair in zip(first, second, strict=True)))
    block = _tangent_block(rows)
    kept.update(first=first, second=second, rows=rows, block=block)
    return t1, t2, rows, block


def _tangent_block(rows: _Rows) -> _TangentBlock:
    """The ``_TangentBlock`` of the two tangent rows ``rows`` (jacobian and response
    (c, 2, 12), mass and inverse mass (c, 2)).

    ``K = [[k11, k12], [k12, k22]]`` with ``k11, k22`` the rows' inverse masses and
    ``k12 = J_t1 · M⁻¹J_t2ᵀ``. With the rows' masses ``m_i = 1/k_ii`` and ``c² = m1 m2 k12²``
    (< 1: K is positive definite), ``K⁻¹ = [[m1, -m1 m2 k12], [-m1 m2 k12, m2]] / (1 - c²)``,
    which is the rows' own masses, bit for bit, when ``k12`` is zero (a sphere on a
    level ground)."""
    tangent_coupling = einsum("ij,ij->i", rows.jacobian[:, 0], rows.response[:, 1])  # k12
    mass_1, mass_2 = rows.mass[:, 0], rows.mass[:, 1]
    decoupling = 1.0 - mass_1 * mass_2 * tangent_coupling * tangent_coupling  # 1 - c²
    cross_mass = -(mass_1 * mass_2 * tangent_coupling) / decoupling
    sticking_mass = np.stack(
        [
            np.stack([mass_1 / decoupling, cross_mass], axis=1),
            np.stack([cross_mass, mass_2 / decoupling], axis=1),
        ],
        axis=1,
    )
    step_mass = 2.0 / (rows.inverse_mass[:, 0] + rows.inverse_mass[:, 1])
    return _TangentBlock(sticking_mass, step_mass)


def _normal_velocity(body_twist: np.ndarray, graph: _ContactGraph, rows: _Rows) -> np.ndarray:
    """(c,) m/s, ``J · [twist_A, twist_B]`` of each contact's normal row."""
    twist = body_twist.take(graph.pair_rows, axis=0).reshape(-1, 12)
    return einsum("ij,ij->i", rows.jacobian, twist)


def _per_colour(batches: list[slice], *arrays: np.ndarray) -> list[tuple[np.ndarray, ...]]:
    """Per colour, the views ``array[s]`` of each of ``arrays``: taken once per solve instead
    of once per sweep (one colour: the arrays themselves)."""
    if len(batches) == 1:
        return [arrays]
    return list(zip(*[[array[s] for s in batches] for array in arrays], strict=True))


def _normal_colours(
    graph: _ContactGraph, rows: _Rows, target: np.ndarray, impulse: np.ndarray
) -> list[tuple[np.ndarray, ...]]:
    """Per colour, the views ``_sweep_normal`` works on: flat twist indices, Jacobian,
    response, effective mass, target and accumulated impulse (updated in place)."""
    return _per_colour(
        graph.batches,
        graph.twist_index,
        rows.jacobian,
        rows.response,
        rows.mass,
        target,
        impulse,
    )


def _sweep_normal(
    body_twist: np.ndarray, colours: list, impulse: np.ndarray, mass: np.ndarray
) -> float:
    """One Gauss-Seidel sweep over the colours (``_normal_colours`` of ``impulse`` and the
    rows' ``mass``); returns the largest velocity change, m/s.

    The change of a contact is its impulse change over its effective mass (what the sweep
    did to its own relative normal velocity), measured once per sweep. Gathers and stores go
    through the flat twist indices (``take`` and ``put``: faster than fancy indexing).
    Every step makes a new array: on arrays of a few elements an in-place update costs
    more than the allocation it saves.
    """
    start = impulse.copy()
    flat_twist = body_twist.reshape(-1)  # a view: body_twist is C-contiguous
    for index, jacobian, response, rows_mass, target, rows_impulse in colours:
        twist, _ = _colour_update(
            flat_twist.take(index), jacobian, response, rows_mass, target, rows_impulse
        )
        flat_twist.put(index, twist)
    return float((np.abs(impulse - start) / mass).max())


def _colour_update(
    twist, jacobian, response, mass, target, impulse
) -> tuple[np.ndarray, np.ndarray]:
    """The twists (k, 12) ``[twist_A, twist_B]`` of k contacts sharing no dynamic body after
    one update from ``twist (k, 12)``, and the impulse changes (k,) N·s: each contact's
    impulse reaches its target velocity ``target (k,)`` m/s, the accumulated ``impulse (k,)``
    N·s (updated in place) kept >= 0; ``jacobian, response (k, 12)`` and effective
    ``mass (k,)`` kg are its rows'."""
    velocity = einsum("ij,ij->i", jacobian, twist)
    accumulated = np.maximum(impulse + mass * (target - velocity), 0.0)
    delta = accumulated - impulse
    impulse[...] = accumulated
    return twist + delta[:, None] * response, delta


def _friction_colours(
    graph: _ContactGraph,
    rows: _Rows,
    block: _TangentBlock,
    normal_impulse: np.ndarray,
    impulse: np.ndarray,
) -> list[tuple[np.ndarray, ...]]:
    """Per colour, the views ``_sweep_friction`` works on: flat twist indices, the tangent
    rows' Jacobian and response (k, 2, 12), the block's sticking and step masses, the
    friction coefficients, the normal impulses and the accumulated friction impulses (both
    updated in place by the sweeps)."""
    return _per_colour(
        graph.batches,
        graph.twist_index,
        rows.jacobian,
        rows.response,
        block.sticking_mass,
        block.step_mass,
        graph.friction,
        normal_impulse,
        impulse,
    )


def _sweep_friction(
    body_twist: np.ndarray, colours: list, impulse: np.ndarray, mass: np.ndarray
) -> float:
    """One Gauss-Seidel sweep over the colours (``_friction_colours``) of the two tangent rows
    per contact, each contact's accumulated impulse ``impulse (c, 2)`` N·s (in place) updated
    by ``_friction_update`` within its disc ``μ λ_n``.

    ``mass (c, 2)`` kg are the tangent rows' effective masses. Returns the largest tangential
    velocity change, m/s (each row's impulse change over its own effective mass, as
    ``_sweep_normal`` measures).
    """
    start = impulse.copy()
    flat_twist = body_twist.reshape(-1)  # a view: body_twist is C-contiguous
    for (
        index,
        jacobian,
        response,
        sticking_mass,
        step_mass,
        friction,
        normal_impulse,
        rows_impulse,
    ) in colours:
        twist = flat_twist.take(index)
        accumulated = _friction_update(
            einsum("ikj,ij->ik", jacobian, twist),
            rows_impulse,
            sticking_mass,
            step_mass,
            friction * normal_impulse,
        )
        delta = accumulated - rows_impulse
        rows_impulse[...] = accumulated
        twist += einsum("ik,ikj->ij", delta, response)
        flat_twist.put(index, twist)
    return float(np.max(np.abs(impulse - start) / mass))


def _friction_update(
    contact_slip: np.ndarray,
    contact_impulse: np.ndarray,
    sticking_mass: np.ndarray,
    step_mass: np.ndarray,
    disc_radius: np.ndarray,
) -> np.ndarray:
    """The new accumulated friction impulses (k, 2) N·s of k contacts sharing no dynamic body:
    isotropic Coulomb friction, whatever the tangent basis.

    Args:
        contact_slip: (k, 2) m/s, each contact's slip ``v = J_t · [twist_A, twist_B]`` along
            its tangents (t1, t2) as the sweep sees it now, the current impulse included.
        contact_impulse: (k, 2) N·s, the accumulated friction impulses ``λ`` so far.
        sticking_mass, step_mass: (k, 2, 2) and (k,) kg, the ``_TangentBlock``'s ``K⁻¹``
            and ``τ = 2 / tr K``.
        disc_radius: (k,) N·s, ``μ λ_n``.

    Changing a contact's impulse from ``λ`` to ``λ'`` changes its slip to
    ``v' = v + K (λ' - λ)`` and the bodies' kinetic energy to
    ``E(λ') = ½ (λ' - λ_s)ᵀ K (λ' - λ_s)`` + const, where ``λ_s = λ - K⁻¹ v`` is the sticking
    impulse (``v' = 0``) and ``∇E = v'``. Coulomb friction with maximal dissipation is the
    ``λ'`` of the disc ``|λ'| <= μ λ_n`` with the least ``E``: ``λ_s`` when it lies in the
    disc (sticking), else a ``λ'`` on the circle ``|λ'| = μ λ_n`` with ``v' = -s λ'/|λ'|``,
    ``s > 0`` (the KKT conditions): friction of magnitude μ λ_n opposing the slip it
    leaves. The update is

    - sticking: ``λ_s`` if it fits (the full block: one update brings the slip to zero);
    - sliding: ``λ' = P(λ - τ v)``, ``P`` the radial projection onto the disc: a projected
      gradient step of ``E`` with the scalar mass ``τ``, i.e. the current impulse moved
      against the contact's current slip, then cut to the disc.

    Why this direction rule is right. A contact that no longer changes has ``λ' = λ``, so
    ``v' = v``. Were ``|λ - τ v| <= μ λ_n``, ``P`` would keep it, ``λ = λ - τ v`` gives
    ``v = 0`` and ``λ_s = λ`` would have fitted; so ``|λ - τ v| > μ λ_n``,
    ``λ = μ λ_n (λ - τ v)/|λ - τ v|`` and ``τ v = -(|λ - τ v| / (μ λ_n) - 1) λ``: at
    convergence the friction impulse has magnitude μ λ_n and is antiparallel to the
    contact's final slip, in any tangent basis (``τ`` is a scalar and ``P`` commutes with
    rotations about the normal). It is stable: near that state (the other contacts held) an
    error of angle ε in ``λ`` along ``w ⊥ λ`` comes back as
    ``ε (1 - τ wᵀKw) / (1 + τ s / (μ λ_n))``, at most ``(κ - 1)/(κ + 1)`` of ε with ``κ``
    K's condition number (``τ = 2/tr K = 2/(k_min + k_max)`` is the step that makes this
    bound least), and far less while the slip ``s`` is large. A sphere's ``K = k·1`` gives
    ``τ = 1/k``: ``λ - τ v = λ_s`` and one update is exact, with the same operations as the
    rule it replaces.

    The rules not taken: clamping a trial built with each row's own mass (``λ - diag(m) v``,
    the rule it replaces) converges to friction along ``-diag(m) v``, not ``-v`` (the two
    row masses of a rectangular box's corner differ; measured: a 0.4 x 0.2 m box pushed
    at 1 m/s at 30° on μ = 0.4 had moved at 37.6° after 0.2 s); stepping straight against
    ``v`` (``τ → ∞``) has the gain ``μ λ_n wᵀKw / s``, above 1 as a contact comes to a stop
    (measured: that box yawing at 0.023 rad/s as it stopped).

    A slip of zero with ``λ_s`` outside the disc (the normal impulse fell below a
    warm-started friction impulse) keeps the impulse's direction, cut to the disc; a zero
    ``λ - τ v`` gives a zero impulse for this update (``TINY_IMPULSE``).
    """
    sticking = contact_impulse - (sticking_mass @ contact_slip[:, :, None])[:, :, 0]
    sticks = np.sqrt(einsum("ik,ik->i", sticking, sticking)) <= disc_radius
    if np.logical_and.reduce(sticks):  # all stick (sticks.all() without its Python layer):
        # resting contacts: the sliding step is not needed (the same values)
        return sticking
    sliding = contact_impulse - step_mass[:, None] * contact_slip
    sliding_norm = np.sqrt(einsum("ik,ik->i", sliding, sliding))
    on_disc = (
        sliding * np.minimum(1.0, disc_radius / np.maximum(sliding_norm, TINY_IMPULSE))[:, None]
    )
    return np.where(sticks[:, None], sticking, on_disc)


class ContactSolution(NamedTuple):
    """Result of ``solve_contacts``.

    Attributes:
        vel: (n, 3) m/s, world frame, after the impulses.
        ang_vel: (n, 3) rad/s, world frame, after the impulses.
        report: per-contact record of the step.
        pseudo_twist: (n, 6) or None; split-impulse position-correction velocities
            ``[v (3) m/s, ω (3) rad/s]``, world frame, applied to the pose only.
    """

    vel: np.ndarray
    ang_vel: np.ndarray
    report: ContactReport
    pseudo_twist: np.ndarray | None


def solve_contacts(
    model: Model,
    contacts: Contacts,
    pos: np.ndarray,
    inv_inertia_world: np.ndarray,
    vel: np.ndarray,
    ang_vel: np.ndarray,
    settings: Settings,
    previous: ContactReport | None = None,
) -> ContactSolution:
    """Apply contact impulses to the velocities ``vel, ang_vel (n, 3)`` (world frame).

    Args:
        contacts: detected at the start of the step (``pos`` are those positions).
        inv_inertia_world: (n, 3, 3) ``R I⁻¹ Rᵀ``, zero for fixed bodies.
        previous: the last step's report, for warm starting (``Settings.warm_start``).
    """
    if contacts.count == 0:
        return ContactSolution(vel, ang_vel, ContactReport.empty(), None)
    n = model.n_bodies

    # colour the contact graph and put each colour in one contiguous slice
    work = workspace(model)
    graph = _contact_graph(model, work, contacts, settings)
    contacts = _in_colour_order(contacts, graph)

    # pre-step: arms, Jacobians, effective masses, targets from the approach speed
    a, b = graph.body_a, graph.body_b
    arm_a, arm_b = contacts.point - pos.take(a, axis=0), contacts.point - pos.take(b, axis=0)
    inv_inertia_a = inv_inertia_world.take(a, axis=0)
    inv_inertia_b = inv_inertia_world.take(b, axis=0)
    geometry = (arm_a, arm_b, inv_inertia_a, inv_inertia_b)
    normal_rows = _kept_rows(_kept(work, "normal"), graph, contacts.normal, *geometry)
    body_twist = np.zeros((n + 1, 6))
    body_twist[:n, :3], body_twist[:n, 3:] = vel, ang_vel
    contact_twist = body_twist.take(graph.pair_rows, axis=0).reshape(-1, 12)
    before = einsum("ij,ij->i", normal_rows.jacobian, contact_twist)
    target = _normal_targets(contacts.depth, before, graph.negative_restitution, settings)

    # warm start (last step's impulses at the matching contacts), then sequential impulses
    impulse, previous_friction = _warm_start_impulses(model, graph, contacts, previous, settings)
    if graph.gathered:
        sweeps, after = _solve_gathered(
            body_twist, contact_twist, graph, normal_rows, target, impulse, settings
        )
        friction_impulse = graph.no_friction_impulse
    else:
        sweeps, after, friction_impulse = _solve_coloured(
            body_twist,
            graph,
            work,
            contacts,
            geometry,
            normal_rows,
            target,
            impulse,
            previous_friction,
            settings,
        )
    report = ContactReport(
        contacts, graph.restitution, before, after, impulse, friction_impulse, sweeps
    )
    pseudo = (
        _split_impulse(n + 1, graph, normal_rows, contacts.depth, settings)
        if settings.position_correction == "split_impulse"
        else None
    )
    return ContactSolution(body_twist[:n, :3].copy(), body_twist[:n, 3:].copy(), report, pseudo)


def _solve_coloured(
    body_twist: np.ndarray,
    graph: _ContactGraph,
    work: Workspace,
    contacts: Contacts,
    geometry: tuple,
    normal_rows: _Rows,
    target: np.ndarray,
    impulse: np.ndarray,
    previous_friction: np.ndarray | None,
    settings: Settings,
) -> tuple[int, np.ndarray, np.ndarray]:
    """Warm start and sweeps colour by colour, normal rows then friction rows, on
    ``body_twist (n + 1, 6)`` in place; ``impulse (c,)`` N·s accumulates in place.

    Returns the sweeps used, the normal velocities after (c,) m/s and the friction
    impulses (c, 3) N·s, world frame.
    """
    _apply_impulses(body_twist, graph, normal_rows.response, impulse)
    if graph.use_friction:
        t1, t2, tangent_rows, tangent_block = _tangent_rows(work, graph, contacts.normal, geometry)
        tangent_impulse = np.stack(
            [np.sum(previous_friction * t1, axis=1), np.sum(previous_friction * t2, axis=1)], axis=1
        )
        for k in range(2):
            _apply_impulses(body_twist, graph, tangent_rows.response[:, k], tangent_impulse[:, k])

    colours = _normal_colours(graph, normal_rows, target, impulse)
    if graph.use_friction:
        friction_colours = _friction_colours(
            graph, tangent_rows, tangent_block, impulse, tangent_impulse
        )
    sweeps = 0
    for sweeps in range(1, settings.solver_iterations + 1):  # noqa: B007 (count kept for the report)
        largest = _sweep_normal(body_twist, colours, impulse, normal_rows.mass)
        if graph.use_friction:
            largest = max(
                largest,
                _sweep_friction(body_twist, friction_colours, tangent_impulse, tangent_rows.mass),
            )
        if largest <= settings.solver_tolerance:
            break

    after = _normal_velocity(body_twist, graph, normal_rows)
    friction_impulse = (
        tangent_impulse[:, :1] * t1 + tangent_impulse[:, 1:] * t2
        if graph.use_friction
        else graph.no_friction_impulse
    )
    return sweeps, after, friction_impulse


def _solve_gathered(
    body_twist: np.ndarray,
    contact_twist: np.ndarray,
    graph: _ContactGraph,
    normal_rows: _Rows,
    target: np.ndarray,
    impulse: np.ndarray,
    settings: Settings,
) -> tuple[int, np.ndarray]:
    """``_solve_coloured`` for a ``graph.gathered`` graph: the same operations on the
    contacts' twists ``contact_twist (c, 12)`` (``[twist_A, twist_B]``, gathered from
    ``body_twist``), stored into ``body_twist`` once at the end instead of after every
    update (no twist row is shared, so every gather would read back the last store).

    Returns the sweeps used and the normal velocities after (c,) m/s.
    """
    if np.count_nonzero(impulse):
        contact_twist = contact_twist + impulse[:, None] * normal_rows.response
    sweeps = 0
    for sweeps in range(1, settings.solver_iterations + 1):  # noqa: B007 (count kept for the report)
        contact_twist, delta = _colour_update(
            contact_twist,
            normal_rows.jacobian,
            normal_rows.response,
            normal_rows.mass,
            target,
            impulse,
        )
        # the sweep's impulse change is the one colour's: _sweep_normal's measure
        if float((np.abs(delta) / normal_rows.mass).max()) <= settings.solver_tolerance:
            break
    body_twist.reshape(-1)[graph.twist_index] = contact_twist
    return sweeps, einsum("ij,ij->i", normal_rows.jacobian, contact_twist)


def _apply_impulses(body_twist, graph: _ContactGraph, response, impulse) -> None:
    """Add the impulses ``impulse (c,)`` along rows with ``response (c, 12)`` to the twists."""
    if not np.count_nonzero(impulse):
        return
    flat_twist = body_twist.reshape(-1)  # a view: body_twist is C-contiguous
    for index, rows_response, rows_impulse in _per_colour(
        graph.batches, graph.twist_index, response, impulse
    ):  # contacts of one colour share no dynamic body: gather, add, store
        flat_twist.put(index, flat_twist.take(index) + rows_impulse[:, None] * rows_response)


def _warm_start_impulses(
    model: Model,
    graph: _ContactGraph,
    contacts: Contacts,
    previous: ContactReport | None,
    settings: Settings,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Initial normal impulses (c,) N·s and friction impulses (c, 3) N·s, world frame (None
    when no contact has friction).

    Each contact takes the accumulated impulses of the nearest contact of the same body
    pair in ``previous`` if that one lies within ``WARM_START_MATCH_FRACTION`` of the
    pair's smaller bounding radius; otherwise it starts from zero. A first impact has no
    previous contact, so the documented single impulse is unchanged by warm starting.
    """
    count = contacts.count
    if not settings.warm_start or previous is None or previous.contacts.count == 0:
        return np.zeros(count), np.zeros((count, 3)) if graph.use_friction else None
    source, matched = _warm_start_match(model, graph, contacts, previous.contacts)
    carried = previous.normal_impulse if source is None else previous.normal_impulse[source]
    normal = np.where(matched, carried, 0.0)
    if not graph.use_friction:
        return normal, None
    carried = previous.friction_impulse if source is None else previous.friction_impulse[source]
    return normal, np.where(matched[:, None], carried, 0.0)


def _warm_start_match(
    model: Model, graph: _ContactGraph, contacts: Contacts, old: Contacts
) -> tuple[np.ndarray | None, np.ndarray]:
    """The old contact ``source (c,)`` int each contact continues (None: contact ``i``
    continues old contact ``i``) and whether it is a match ``matched (c,)`` bool."""
    n = model.n_bodies
    if old.body_a is graph.body_a and old.body_b is graph.body_b and graph.unique_pairs:
        # the last step's graph: each pair's one old contact has the same index
        offset = old.point - contacts.point
        return None, np.add.reduce(offset * offset, axis=1) <= graph.match_distance_sq
    if old.count == 1:  # one old contact (a body resting on the ground): nothing to search
        source = np.zeros(contacts.count, dtype=np.int64)
        same_pair = (contacts.body_a == old.body_a[0]) & (contacts.body_b == old.body_b[0])
        distance_sq = last_axis_sum((old.point[source] - contacts.point) ** 2)
        return source, same_pair & (distance_sq <= graph.match_distance_sq)
    old_key = old.body_a * n + old.body_b
    key = graph.pair_key
    order = np.argsort(old_key, kind="stable")
    sorted_key = old_key[order]
    start = np.searchsorted(sorted_key, key, side="left")
    end = np.searchsorted(sorted_key, key, side="right")
    width = int(max((end - start).max(), 1))
    if width == 1:  # at most one old contact per pair (spheres): no (c, width) candidates
        source = order[np.minimum(start, order.size - 1)]
        distance_sq = np.sum((old.point[source] - contacts.point) ** 2, axis=1)
        return source, (start < end) & (distance_sq <= graph.match_distance_sq)
    slot = start[:, None] + np.arange(width)[None, :]
    valid = slot < end[:, None]
    candidate = order[np.minimum(slot, order.size - 1)]
    distance_sq = np.sum((old.point[candidate] - contacts.point[:, None, :]) ** 2, axis=2)
    distance_sq[~valid] = np.inf
    best = np.argmin(distance_sq, axis=1)
    rows = np.arange(contacts.count)
    matched = distance_sq[rows, best] <= graph.match_distance_sq
    return candidate[rows, best], matched


def _correction_speed(depth: np.ndarray, settings: Settings) -> np.ndarray:
    """Bias velocity (c,) m/s removing β of the penetration beyond the slop per step, capped."""
    excess = np.maximum(depth - settings.penetration_slop, 0.0)
    return np.minimum(
        settings.baumgarte_factor * excess / settings.dt, settings.max_correction_speed
    )


def _normal_targets(depth, before, negative_restitution, settings: Settings) -> np.ndarray:
    """Target normal velocity (c,) m/s of each contact after the solve.

    Contacts approaching faster than the threshold bounce: ``-e (v_rel·n)`` (Newton's law,
    from the approach speed before the solve); the others target 0 (they stop approaching).
    Every reported contact counts as touching, including those separated by less than
    ``Settings.contact_margin``. Baumgarte adds its bias velocity as a floor.
    """
    bounce = before < -settings.restitution_threshold
    target = np.where(bounce, negative_restitution * before, 0.0)
    if settings.position_correction == "baumgarte":
        target = np.maximum(target, _correction_speed(depth, settings))
    return target


def _split_impulse(
    rows_count: int, graph: _ContactGraph, normal_rows: _Rows, depth, settings: Settings
) -> np.ndarray:
    """Pseudo-velocities (n, 6) that remove penetration through the pose only (split impulse).

    The same sequential-impulse sweeps, on a twist array that starts at zero and targets
    the Baumgarte bias; the result moves positions this step and is then discarded, so no
    kinetic energy is added.
    """
    pseudo = np.zeros((rows_count, 6))
    target = _correction_speed(depth, settings)
    if not np.any(target > 0.0):
        return pseudo[:-1]
    impulse = np.zeros(depth.size)
    colours = _normal_colours(graph, normal_rows, target, impulse)
    for _ in range(settings.position_iterations):
        if _sweep_normal(pseudo, colours, impulse, normal_rows.mass) <= settings.solver_tolerance:
            break
    return pseudo[:-1]
