"""
A support's load as a person reads it: the static weight and the rotating part.

The engine's load is linear in gravity, omega^2 and alpha, so each support's
force (stator frame) splits exactly into

* the **static** part: the load at rest at the same rotor angle (gravity alone),
  constant for an untilted rotor;
* the **rotating** part: the rest (omega^2 and alpha terms of the unbalance), the
  load without gravity, fixed in the rotor frame, so in the stator frame it turns
  once a revolution with a constant amplitude.

Their sum is the engine's load (to rounding).

Plotting the two amplitudes shows what the unbalance does at each speed without
the once-a-turn swing of the raw components. Newtons, arrays over samples.
"""

from dataclasses import dataclass

import numpy as np

from cvc_balance.physics.engine import loads


@dataclass(frozen=True)
class SupportLoadParts:
    """Per support name, (n,) arrays in N: static weight and rotating amplitude."""

    static: dict
    rotating: dict


def support_load_parts(model, q, omega, alpha, gravity=None):
    """
    Split the support loads into static weight and rotating amplitude (N), per sample.

    ``q`` (rad), ``omega`` (rad/s), ``alpha`` (rad/s^2): arrays of the samples;
    ``gravity`` as :func:`loads` takes it. Each part is computed on its own, not as a
    difference, so a balanced rotor's rotating part is exactly 0 (a difference would
    leave the rounding of the weight): the static part is the load at rest (gravity
    alone), the rotating part the load without gravity.
    """
    at_rest = loads(model, q, 0.0, 0.0, gravity)
    turning = loads(model, q, omega, alpha, (0.0, 0.0, 0.0))
    static = {s.name: np.linalg.norm(at_rest.support_force[s.name], axis=1)
              for s in model.supports}
    rotating = {s.name: np.linalg.norm(turning.support_force[s.name], axis=1)
                for s in model.supports}
    return SupportLoadParts(static, rotating)
