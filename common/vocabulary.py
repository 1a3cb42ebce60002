"""Names every layer shares: the law's modes (more vocabulary joins as the layers are split)."""
from __future__ import annotations

import enum


class Mode(enum.IntEnum):
    """The law's mode in one period (docs/controller.md)."""

    TRACK = 0
    AVOID = 1
    ROTATE = 2
