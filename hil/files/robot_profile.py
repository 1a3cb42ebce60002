"""Robot profiles: a robot's wheels and drivers in a file of its own, shared between users.

::

    name = "cart"                   # optional
    description = "..."             # optional
    [robot]                         # agent.config.RobotParams (wheel_radius, wheel_base,
                                    # wheel_speed_limit, wheel_ramp, drive_latency,
                                    # watchdog_timeout), all optional

``--robot FILE`` of ``sim`` and ``sitl`` replaces the scenario's ``[robot]`` table with the
profile's (``robots/`` has the paper's ideal robot and two real ones). Every problem raises
:class:`common.schema.ConfigError` naming the file and the field.
"""
from __future__ import annotations

from pathlib import Path

from agent.config import RobotParams
from common.schema import TableReader, from_table, load_toml

TOP_KEYS = {"name", "description", "robot"}
BUNDLED = Path(__file__).resolve().parents[2] / "robots"     # the repository's profiles
SITL_DEFAULT = BUNDLED / "cart.toml"     # the robot a SITL runs unless told otherwise


def load_robot_profile(path: str | Path) -> RobotParams:
    """The ``[robot]`` table of the profile at ``path``, validated."""
    path = Path(path)
    doc = load_toml(path, "the robot profile")
    rd = TableReader(str(path))
    rd.only(doc, TOP_KEYS, "top level")
    for key in ("name", "description"):
        if key in doc:
            rd.string(doc, key, key)
    if "robot" not in doc:
        raise rd.fail("[robot]", "missing: a profile is its [robot] table")
    return from_table(RobotParams, rd.table(doc, "robot"), f"{path} [robot]")
