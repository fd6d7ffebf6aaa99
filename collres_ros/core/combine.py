"""Combine rules: one coefficient per contact from the two bodies' coefficients.

Pure functions over numpy arrays (rapier style: the rule is a string naming
an enum value of ``config.RESTITUTION_RULES`` / ``config.FRICTION_RULES``).

Restitution rules ``average``, ``min``, ``max`` and ``multiply`` give one
coefficient e per contact: the same impulse acts on both bodies, so linear
and angular momentum are conserved. ``per_object`` is the textbook per-body model:
body A's impulse j_A uses A's own coefficient and body B's j_B uses B's,
so when e_A != e_B the two impulses differ and momentum is NOT conserved
(it changes by (e_A - e_B) j0 n, j0 the inelastic impulse). It is offered
for fidelity to that textbook model, never as the default.
"""

from __future__ import annotations

import numpy as np

from collres_ros.core.config import FRICTION_RULES, RESTITUTION_RULES


def _pairwise(a: np.ndarray, b: np.ndarray, rule: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if rule == 'average':
        return 0.5 * (a + b)
    if rule == 'min':
        return np.minimum(a, b)
    if rule == 'max':
        return np.maximum(a, b)
    if rule == 'multiply':
        return a * b
    if rule == 'geometric':
        return np.sqrt(a * b)
    raise ValueError(f'unknown combine rule {rule!r}')


def combine_restitution(ea: np.ndarray, eb: np.ndarray, rule: str) -> np.ndarray:
    """One restitution coefficient per contact (dimensionless, 0..1).

    For ``per_object`` there is no single coefficient; this returns the mean,
    which is used only for reporting (see ``restitution_per_side``).
    """
    if rule not in RESTITUTION_RULES:
        raise ValueError(f'unknown restitution rule {rule!r}')
    return _pairwise(ea, eb, 'average' if rule == 'per_object' else rule)


def restitution_per_side(ea: np.ndarray, eb: np.ndarray,
                         rule: str) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (e on A's impulse, e on B's impulse) per contact.

    Equal for every rule but ``per_object``, where they are the bodies' own.
    """
    if rule == 'per_object':
        return np.asarray(ea, dtype=float), np.asarray(eb, dtype=float)
    e = combine_restitution(ea, eb, rule)
    return e, e


def combine_friction(mua: np.ndarray, mub: np.ndarray, rule: str) -> np.ndarray:
    """One friction coefficient per contact; ``geometric`` = sqrt(mu_a mu_b) (Box2D, Jolt)."""
    if rule not in FRICTION_RULES:
        raise ValueError(f'unknown friction rule {rule!r}')
    return _pairwise(mua, mub, rule)
