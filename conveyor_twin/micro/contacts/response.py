"""Contact response: impulses (sequential impulses) or penalty spring-dampers (Rideout, Stein).

The two models, one module each, with what they share here (the friction law and the model
codes of ``cfg[CF_MODE]``):

- :mod:`.impulses`, the impulse model: equal and opposite impulses at each contact point,
  solved as sequential impulses with a warm start (:func:`~.impulses.prepare_contacts`,
  :func:`~.impulses.solve_impulses`), restitution above
  :data:`~.impulses.RESTITUTION_THRESHOLD` in a pass of its own (:mod:`.restitution`), and the
  penetration correction by positions only (:func:`~.impulses.correct_positions`); every sweep
  keeps momentum;
- :mod:`.energy`: the kinetic energy the impulses may add, bounded per island of parts by the
  external work on it (:func:`~.energy.limit_energy`);
- :mod:`.penalty`, the penalty model: a spring-damper per contact point,
  ``f_n = max(0, k d - c u_n)``, and a Coulomb friction force ``min(mu f_n, |u_t| / (k_t dt))``
  against the sliding (:func:`~.penalty.penalty_forces`); no position correction.

Friction follows Horváth et al.'s speed-dependent coefficient (:func:`friction_coefficient`:
static at rest, sliding above the transition speed, linear in between).

The interface: the narrow phase's records ``ct`` (C, CT_COLUMNS) and bodies ``cidx`` (C, 2)
(``nc`` of them, canonical order) in, with ``prev`` (the previous substep's keys and impulses);
the parts' velocities (impulse model: ``prepare_contacts``, ``solve_impulses``,
``limit_energy``; penalty model: ``penalty_forces`` into force arrays) and positions
(``correct_positions``) updated in place, the activities ``acc`` accumulated. Nothing here
looks at geometry beyond the records.
"""

from numba import njit

MODE_IMPULSE = 0
MODE_PENALTY = 1


@njit(cache=True, inline='always')
def friction_coefficient(mu_s, mu_k, v_t, speed):
    """Return Horváth et al.'s friction coefficient at tangential ``speed`` [m/s]."""
    if speed >= v_t:
        return mu_k
    return mu_s + (mu_k - mu_s) * (speed / v_t)

