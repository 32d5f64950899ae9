"""Wakes: fish swimming behind others meet less drag (a model of drafting, off by default).

Fish in a school spend less to swim than alone, and most in the trailing positions, where
the flow left by the fish ahead helps them along (Marras et al. 2015, Behav. Ecol.
Sociobiol. 69:219, tail-beat frequency of grey mullet in a school; Weihs 1973, Nature
241:290, on the diamond pattern). The simulator models that with one number per fish and
control period, its *shelter* in [0, 1], which lowers its surge drag to (1 − saving ×
shelter) of the still-water value:

- the wake of fish j is a cylinder behind it, along its heading, ``length`` long and
  ``width`` in radius;
- a fish i inside it at a distance d behind j and r off j's axis gets (1 − d/length) ×
  (1 − r/width) from it, if j swims forward through the water (a fish drifting backwards
  leaves no wake worth having);
- a fish takes the best shelter any one fish ahead gives it (wakes do not add up).

How much a wake saves is not measured for BlueBots: ``saving`` is a modelling choice
(docs/formations.md states the values used), meant to make a formation's front costlier
than its rear so that effort sharing can be studied, not to predict a BlueBot's energy use.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.dynamics import State

WAKE_LENGTH = 0.5
"""How far behind a swimming fish its wake reaches by default, m."""
WAKE_WIDTH = 0.15
"""The default radius of a fish's wake about its axis, m."""

FloatArray = NDArray[np.float64]


def wake_shelter(state: State, *, length: float, width: float) -> FloatArray:
    """(N,) each fish's shelter in [0, 1] from the wakes of the fish ahead of it.

    Args:
        state: the fish now (positions, headings, velocities through the water).
        length: how far behind a fish its wake reaches, m.
        width: the wake's radius about the fish's axis, m.

    Raises:
        ValueError: a length or width that is not positive.
    """
    if not (length > 0 and width > 0):
        raise ValueError(f"a wake needs a positive length and width, got {length}, {width}")
    count = state.position.shape[0]
    if count < 2:
        return np.zeros(count)
    heading = np.stack([np.cos(state.yaw), np.sin(state.yaw), np.zeros(count)], axis=1)
    # offset[j, i]: where fish i is from fish j.
    offset = state.position[None, :, :] - state.position[:, None, :]
    behind = -np.einsum("jid,jd->ji", offset, heading)
    across = np.linalg.norm(offset + behind[:, :, None] * heading[:, None, :], axis=2)
    inside = (behind > 0) & (behind < length) & (across < width)
    inside &= (state.body_velocity[:, 0] > 0)[:, None]
    np.fill_diagonal(inside, False)
    shelter = np.where(inside, (1 - behind / length) * (1 - across / width), 0.0)
    result: FloatArray = shelter.max(axis=0)
    return result
