"""Defaults of a robot's two ODrive wheel drivers, written once for every side that needs
them: the agent's settings (agent.config.RobotParams, the CAN node ids), the host side of the
drivers (transport.wheel_drivers) and the emulated drivers (firmware_sim.odrive_sim)."""
from __future__ import annotations

LEFT_NODE = 0              # CAN node id of the left wheel's driver
RIGHT_NODE = 1             # CAN node id of the right wheel's driver
SPEED_LIMIT = 10.0         # rev/s, velocity limit per wheel
RAMP = 1000.0              # rev/s^2, velocity ramp rate (VEL_RAMP input mode)
CURRENT_LIMIT = 20.0       # A, motor current limit
WATCHDOG = 0.1             # s, default watchdog timeout: a driver without a CAN frame for
                           # this long in closed loop goes IDLE (robot profile: watchdog_timeout)
WATCHDOG_MAX = 10.0        # s, the longest watchdog timeout a robot profile may give
