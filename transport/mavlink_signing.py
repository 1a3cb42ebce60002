"""MAVLink 2 message signing: the key file and the check of incoming frames.

Reading the key file (:func:`load_signing_key`) is the module's only I/O; the check works on
frames handed in, with the time passed in.

Outgoing frames are signed by pymavlink's encoder (``MAVLink.signing``). Incoming frames are
checked here, on the raw frame, rather than by pymavlink's decoder, for two reasons:
pymavlink stores a stream's timestamp *before* it compares the signature, so one forged
frame with a far-future timestamp makes every later genuine frame of that stream look
replayed; and it does not say why a frame was refused. The rules are the MAVLink 2 ones:

* a signed frame has bit 0 of ``incompat_flags`` set and ends with 13 bytes: link id (1),
  timestamp (6, little-endian, 10 us units since 2015-01-01 00:00 UTC), signature (6) =
  the first 6 bytes of sha256(secret key + frame without the signature);
* a stream is (link id, source system, source component); its timestamps must increase,
  so a frame seen before (a replay) is refused;
* a new stream is accepted only if its timestamp is at most one minute behind the local
  timestamp (which follows the wall clock and the newest accepted frame).

Only frames with a good signature can open or advance a stream.
"""
from __future__ import annotations

import enum
import hashlib
import hmac
from pathlib import Path

KEY_BYTES = 32
EPOCH_2015 = 1420070400            # s, UNIX time of 2015-01-01 00:00 UTC
TICKS_PER_S = 100_000              # signing timestamps count 10 us
NEW_STREAM_WINDOW = 60 * TICKS_PER_S
_MAGIC_V2 = 0xFD
_IFLAG_SIGNED = 0x01
_SIGNATURE_BLOCK = 13


class Verdict(enum.Enum):
    ACCEPTED = "accepted"
    UNSIGNED = "unsigned"
    WRONG_KEY = "wrong key"
    REPLAYED = "replayed or too old"


def signing_timestamp(wall_s: float) -> int:
    """The signing timestamp [10 us since 2015] of UNIX time ``wall_s`` [s]."""
    return int(max(wall_s - EPOCH_2015, 0.0) * TICKS_PER_S)


def load_signing_key(path: str | Path) -> bytes:
    """The 32-byte secret key in ``path``.

    A file of exactly 32 bytes is the raw key. Anything else is a passphrase (ASCII text;
    surrounding white space, e.g. the final newline, is ignored) turned into the key as
    MAVProxy's ``signing setup``/``signing key PASSPHRASE`` does: sha256(passphrase). So a
    passphrase of exactly 32 characters must be followed by a newline.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the MAVLink signing key: {exc.strerror}") from None
    if len(data) == KEY_BYTES:
        return data
    try:
        passphrase = data.decode("ascii").strip()
    except UnicodeDecodeError:
        raise ValueError(f"{path}: a MAVLink signing key file holds 32 raw bytes or an ASCII "
                         f"passphrase; got {len(data)} bytes that are neither") from None
    if not passphrase:
        raise ValueError(f"{path}: the MAVLink signing passphrase is empty")
    return hashlib.sha256(passphrase.encode("ascii")).digest()


class SignatureCheck:
    """Verifies incoming frames against one secret key and remembers each stream's time."""

    def __init__(self, key: bytes):
        if len(key) != KEY_BYTES:
            raise ValueError(f"a MAVLink signing key has {KEY_BYTES} bytes, got {len(key)}")
        self._key = bytes(key)
        self._streams: dict[tuple[int, int, int], int] = {}   # stream -> last timestamp

    def verify(self, frame: bytes, local_timestamp: int) -> tuple[Verdict, int]:
        """The verdict on one whole frame, and the frame's timestamp (0 when unsigned).

        ``local_timestamp`` is the receiver's own signing timestamp (10 us since 2015)."""
        if len(frame) < 10 + _SIGNATURE_BLOCK or frame[0] != _MAGIC_V2 \
                or not frame[2] & _IFLAG_SIGNED:
            return Verdict.UNSIGNED, 0
        link_id = frame[-13]
        stamp = int.from_bytes(frame[-12:-6], "little")
        expected = hashlib.sha256(self._key + bytes(frame[:-6])).digest()[:6]
        if not hmac.compare_digest(expected, bytes(frame[-6:])):
            return Verdict.WRONG_KEY, stamp
        stream = (link_id, frame[5], frame[6])          # link id, source system, component
        last = self._streams.get(stream)
        if (last is not None and stamp <= last) or \
                (last is None and stamp + NEW_STREAM_WINDOW < local_timestamp):
            return Verdict.REPLAYED, stamp
        self._streams[stream] = stamp
        return Verdict.ACCEPTED, stamp
