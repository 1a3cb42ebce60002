"""Counter-based random draws and the link loss process, shared by every imperfect world.

A draw is a hash of its keys (seed, stream, two indices, a counter), so a run is reproducible
from its seed whatever the order in which draws are made, and the batch simulator's compiled
and interpreted runs draw the same numbers. Used by the batch simulator's world
(:mod:`firmware_sim.world_step`, compiled with it) and by the SITL: its plant
(:mod:`firmware_sim.sitl_plant`) and the agents' simulation-only link impairment
(:mod:`agent.impairment`). Plain floats and ints only (numba compiles this module).
"""
from __future__ import annotations

import math

M32 = 0xFFFFFFFF
# streams of draws: the batch world's, then the SITL link impairment's (per link)
LOSS, AGE, SLIP, ENCODER, DETECT, DROPOUT = 1, 2, 3, 4, 5, 6
LINK_LOSS, LINK_AGE = 7, 8


def _mul32(h: int, c: int) -> int:
    """h * c mod 2^32 for h, c < 2^32, with no intermediate above 2^49 (signed overflow is
    undefined in compiled code)."""
    return (h * (c & 0xFFFF) + (((h * (c >> 16)) & 0xFFFF) << 16)) & M32


def _fmix(h: int) -> int:
    """MurmurHash3's 32-bit finaliser."""
    h ^= h >> 16
    h = _mul32(h, 0x85EBCA6B)
    h ^= h >> 13
    h = _mul32(h, 0xC2B2AE35)
    return h ^ (h >> 16)


def _combine(h: int, x: int) -> int:
    """Hash the non-negative integer x (< 2^32) into h."""
    return _fmix((h + _mul32(x & M32, 0x9E3779B1) + 0x7F4A7C15) & M32)


def uniform(seed: int, stream: int, a: int, b: int, step: int) -> float:
    """A uniform draw in (0, 1), a function of its five non-negative integer keys."""
    h = _combine(_combine(_combine(0, seed & M32), seed >> 32), stream)
    h = _combine(_combine(_combine(h, a), b), step)
    return (h + 0.5) / 4294967296.0


def normal(seed: int, stream: int, a: int, b: int, step: int) -> float:
    """A standard normal draw (Box-Muller), a function of its keys."""
    u1 = uniform(seed, stream, a, 2 * b, step)
    u2 = uniform(seed, stream, a, 2 * b + 1, step)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


def loss_step(draw: float, bad: int, loss: float, burst: float) -> int:
    """Whether the next message is lost (1) or not (0), from a uniform ``draw`` and ``bad``,
    what this function returned for the previous message of the channel. ``burst`` 1:
    independent losses of probability ``loss``; > 1: a Gilbert-Elliott channel, every message
    lost in the bad state, none in the good, P(bad -> good) = 1/burst and P(good -> bad) =
    loss / (burst (1 - loss)): long-run loss ``loss``, bursts of ``burst`` messages on average."""
    if burst > 1.0:
        threshold = 1.0 - 1.0 / burst if bad else loss / (burst * (1.0 - loss))
        return 1 if draw < threshold else 0
    return 1 if draw < loss else 0


def loss_burst_problem(loss: float, burst: float) -> str | None:
    """Why bursts of mean length ``burst`` [messages] cannot give the long-run loss ``loss``
    (P(good -> bad) would exceed 1), or None."""
    if loss > 0 and burst > 1 and loss / (1.0 - loss) > burst:
        return (f"a loss of {loss:g} needs bursts of at least {loss / (1 - loss):.3g} "
                f"messages, got {burst:g}")
    return None
