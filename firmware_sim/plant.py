"""How the batch simulator moves its robots (:func:`firmware_sim.swarm_step.advance`).

* ``ideal``: the commands (v, u) applied exactly, as the paper's kinematic model assumes;
* ``wheels``: through the motor drivers' contract: wheel set-points saturated with curvature
  kept, clamped to the velocity limit and ramped at the driver's ramp rate, wheel speeds
  held over each physics substep.
"""
from __future__ import annotations

import enum


class PlantKind(str, enum.Enum):
    IDEAL = "ideal"
    WHEELS = "wheels"
