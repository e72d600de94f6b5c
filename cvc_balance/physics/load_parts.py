"""
A support's load as a person reads it: the static weight and the rotating part.

The engine's load is linear in gravity, omega^2 and alpha, so each support's
force (stator frame) splits exactly into

* the **static** part: the load at rest at the same rotor angle (gravity alone),
  constant for an untilted rotor;
* the **rotating** part: the rest (omega^2 and alpha terms of the unbalance),
  fixed in the rotor frame, so in the stator frame it turns once a revolution
  with a constant amplitude.

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


def support_load_parts(model, q, result, gravity=None):
    """
    Split ``result`` (engine Loads for rotor angles ``q`` rad) per support.

    ``gravity``: as given to :func:`cvc_balance.physics.engine.loads` for ``result``.
    """
    at_rest = loads(model, q, 0.0, 0.0, gravity)
    static, rotating = {}, {}
    for s in model.supports:
        still = at_rest.support_force[s.name]
        static[s.name] = np.linalg.norm(still, axis=1)
        rotating[s.name] = np.linalg.norm(result.support_force[s.name] - still, axis=1)
    return SupportLoadParts(static, rotating)
