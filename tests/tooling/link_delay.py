"""A delaying TCP relay: a slow network link where the kernel has no netem.

    python -m tooling.link_delay --listen HOST:PORT --upstream HOST:PORT --delay-ms N
                                 [--control FILE]        (in tests/, or with it on PYTHONPATH)

Every TCP connection accepted on ``--listen`` is forwarded to ``--upstream``. Each chunk of
bytes read in either direction is written on ``delay`` seconds after it was read: a one-way
delay, so a request-answer round trip through the relay gains 2 x delay. Order within a
direction is kept. Bytes are relayed untouched, so TLS passes through end to end (the
client validates the upstream's certificate against the address it dialled: listen on an
address the certificate names, e.g. the upstream's own IP on another port).

The delay may change while connections are open: :meth:`DelayRelay.set_delay` (seconds), or
a number of milliseconds written into the ``--control`` file (polled every 50 ms; write it
atomically, e.g. to a temporary file renamed over it). A new delay applies to bytes read from
then on; bytes already held keep their release time and nothing overtakes them, so when the
delay drops the held bytes go first and the newer ones follow at once (a burst, as when a
real link's queue drains).

Not emulated: loss, bandwidth, jitter; connection set-up (accept, connect) is not delayed.
Held bytes are buffered without limit (delay x throughput). SIGINT or SIGTERM (or
:meth:`DelayRelay.close`) closes the listening socket and every relayed connection.
"""
from __future__ import annotations

import argparse
import asyncio
import logging
import math
import os
import signal
import sys
import threading
from pathlib import Path

log = logging.getLogger(__name__)

CHUNK = 65536                       # bytes per read
CONTROL_POLL = 0.05                 # s between reads of the control file


def _check_delay(seconds: float) -> float:
    seconds = float(seconds)
    if not (math.isfinite(seconds) and seconds >= 0.0):
        raise ValueError(f"delay must be a finite number of seconds >= 0, got {seconds!r}")
    return seconds


class DelayRelay:
    """Relays TCP from ``listen`` = (host, port) to ``upstream`` = (host, port) with a
    one-way ``delay`` [s] in each direction, on an asyncio loop in a thread of its own.
    ``start()`` binds (port 0: any free port, see ``address``); ``close()`` ends it all."""

    def __init__(self, listen: tuple[str, int], upstream: tuple[str, int], delay: float = 0.0):
        self.listen = (listen[0], int(listen[1]))
        self.upstream = (upstream[0], int(upstream[1]))
        self._delay = _check_delay(delay)
        self.address: tuple[str, int] | None = None     # bound (host, port) once started
        self.accepted = 0                               # connections accepted so far
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._tasks: set[asyncio.Task] = set()                  # connection handlers
        self._writers: set[asyncio.StreamWriter] = set()        # both ends of each

    @property
    def delay(self) -> float:
        """One-way delay [s] applied to bytes read from now on."""
        return self._delay

    def set_delay(self, seconds: float) -> None:
        """Change the one-way delay [s] (thread-safe; see the module notes)."""
        self._delay = _check_delay(seconds)

    def start(self) -> "DelayRelay":
        """Bind and start relaying; raises OSError when the listen address is unusable."""
        if self._thread is not None or self._ready.is_set():
            raise RuntimeError("a relay starts once (make a new one)")
        self._thread = threading.Thread(target=self._run, daemon=True,
                                        name=f"link-delay {self.listen[0]}:{self.listen[1]}")
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            self._thread.join()
            self._thread = None
            raise self._error
        return self

    def close(self, timeout: float = 5.0) -> None:
        """Close the listening socket and every connection, and end the thread."""
        thread, self._thread = self._thread, None
        if thread is None:
            return
        loop, stop = self._loop, self._stop     # both set before start() returns
        try:
            if loop is not None and stop is not None:
                loop.call_soon_threadsafe(stop.set)
        except RuntimeError:            # the loop has already ended
            pass
        thread.join(timeout)
        if thread.is_alive():
            raise RuntimeError("the relay thread did not end")

    def __enter__(self) -> "DelayRelay":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    # --- the loop's thread ---------------------------------------------------------------
    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:        # noqa: BLE001 - handed to start() or logged
            if not self._ready.is_set():
                self._error = exc
            else:
                log.exception("link delay relay failed")
        finally:
            self._ready.set()

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        server = await asyncio.start_server(self._handle, *self.listen, reuse_address=True)
        self.address = tuple(server.sockets[0].getsockname()[:2])
        self._ready.set()
        try:
            await self._stop.wait()
        finally:
            server.close()
            for task in list(self._tasks):
                task.cancel()
            await asyncio.gather(*self._tasks, return_exceptions=True)
            for w in list(self._writers):   # whatever a cancelled handler left open
                w.transport.abort()
            await asyncio.sleep(0)          # abort closes the socket on the next iteration
            await server.wait_closed()

    async def _handle(self, c_reader: asyncio.StreamReader,
                      c_writer: asyncio.StreamWriter) -> None:
        try:
            await self._relay(c_reader, c_writer)
        except asyncio.CancelledError:      # the relay is closing: the end of this task
            pass                            # (asyncio would report a cancelled callback)

    async def _relay(self, c_reader: asyncio.StreamReader,
                     c_writer: asyncio.StreamWriter) -> None:
        """One client connection: connect upstream, then relay both ways until both ends
        have closed (or either fails, or the relay closes)."""
        me = asyncio.current_task()
        if me is not None:                  # always: each connection runs in its own task
            self._tasks.add(me)
        self.accepted += 1
        peer = c_writer.get_extra_info("peername")
        writers = [c_writer]
        self._writers.add(c_writer)
        pumps: list[asyncio.Task] = []
        clean = False
        try:
            try:
                u_reader, u_writer = await asyncio.open_connection(*self.upstream)
            except OSError as exc:
                log.warning("connection from %s dropped: upstream %s:%d: %s", peer,
                            *self.upstream, exc)
                return
            writers.append(u_writer)
            self._writers.add(u_writer)
            log.info("relaying %s -> %s:%d", peer, *self.upstream)
            pumps = [asyncio.create_task(self._pump(c_reader, u_writer)),
                     asyncio.create_task(self._pump(u_reader, c_writer))]
            await asyncio.wait(pumps, return_when=asyncio.FIRST_EXCEPTION)
            failed = [t.exception() for t in pumps if t.done() and t.exception()]
            clean = not failed
            if failed:
                log.info("connection from %s ended: %s", peer, failed[0])
        finally:
            for task in pumps:
                task.cancel()
            for w in writers:               # clean: flush what is left, else drop it
                w.close() if clean else w.transport.abort()
            # cancelled here (the relay closing)? then _main aborts what is left
            await asyncio.gather(*pumps, *(w.wait_closed() for w in writers),
                                 return_exceptions=True)
            self._writers.difference_update(writers)
            self._tasks.discard(asyncio.current_task())

    async def _pump(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """Copy ``reader`` to ``writer``, each chunk held until its read time + delay; the
        end of the stream is passed on (half-close) after the last chunk."""
        loop = asyncio.get_running_loop()
        held: asyncio.Queue = asyncio.Queue()

        async def release() -> None:
            while True:
                due, data = await held.get()
                if data is None:
                    break
                wait = due - loop.time()
                if wait > 0:
                    await asyncio.sleep(wait)
                writer.write(data)
                await writer.drain()
            if writer.can_write_eof():
                writer.write_eof()

        sender = asyncio.create_task(release())
        reading: asyncio.Future | None = None
        try:
            while True:
                reading = asyncio.ensure_future(reader.read(CHUNK))
                done, _ = await asyncio.wait({reading, sender},
                                             return_when=asyncio.FIRST_COMPLETED)
                if sender in done:          # the other side failed while we were reading
                    reading.cancel()
                    sender.result()         # raises its error
                    return
                data = reading.result()
                held.put_nowait((loop.time() + self._delay, data or None))
                if not data:
                    break
            await sender
        finally:
            sender.cancel()
            if reading is not None:
                reading.cancel()


# --- command line --------------------------------------------------------------------------
def _host_port(text: str, lowest: int) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not (sep and host and port.isdigit() and lowest <= int(port) <= 65535):
        raise argparse.ArgumentTypeError(
            f"expected HOST:PORT with a port in {lowest}..65535, got {text!r}")
    return host, int(port)


def _delay_ms(text: str) -> float:
    try:
        ms = float(text)
    except ValueError:
        ms = math.nan
    if not (math.isfinite(ms) and 0.0 <= ms <= 600_000.0):
        raise argparse.ArgumentTypeError(
            f"expected a one-way delay in milliseconds, 0..600000, got {text!r}")
    return ms


class _Control:
    """The --control file: its content is the one-way delay in milliseconds."""

    def __init__(self, path: Path, relay: DelayRelay):
        self.path, self.relay = path, relay
        self.last: str | None = None

    def poll(self) -> None:
        try:
            text = self.path.read_text().strip()
        except OSError:
            return                          # not written (yet): the delay stays
        if not text or text == self.last:
            return
        self.last = text
        try:
            ms = _delay_ms(text)
        except argparse.ArgumentTypeError as exc:
            print(f"link_delay: {self.path}: {exc}; delay stays "
                  f"{self.relay.delay * 1e3:g} ms", file=sys.stderr, flush=True)
            return
        if ms / 1e3 == self.relay.delay:
            return
        self.relay.set_delay(ms / 1e3)
        print(f"link_delay: one-way delay now {ms:g} ms", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tooling.link_delay",
        description="Relay TCP connections with a one-way delay in each direction (bytes "
                    "untouched, so TLS passes through). Stop with SIGINT or SIGTERM.")
    ap.add_argument("--listen", required=True, type=lambda t: _host_port(t, 0),
                    metavar="HOST:PORT", help="address to accept connections on")
    ap.add_argument("--upstream", required=True, type=lambda t: _host_port(t, 1),
                    metavar="HOST:PORT", help="address every connection is forwarded to")
    ap.add_argument("--delay-ms", type=_delay_ms, default=0.0, metavar="N",
                    help="one-way delay [ms] in each direction (default 0)")
    ap.add_argument("--control", type=Path, metavar="FILE",
                    help="file holding the delay [ms]; re-read every 50 ms to change it")
    ap.add_argument("-v", "--verbose", action="store_true", help="log every connection")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    relay = DelayRelay(args.listen, args.upstream, args.delay_ms / 1e3)
    try:
        relay.start()
    except OSError as exc:
        reason = os.strerror(exc.errno) if exc.errno and exc.errno > 0 else str(exc)
        print(f"link_delay: error: cannot listen on {args.listen[0]}:{args.listen[1]}: "
              f"{reason}", file=sys.stderr)
        return 1
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    control = _Control(args.control, relay) if args.control else None
    assert relay.address is not None        # set by start(), which has returned
    host, port = relay.address
    print(f"link_delay: relaying {host}:{port} -> {args.upstream[0]}:{args.upstream[1]}, "
          f"one-way delay {args.delay_ms:g} ms", flush=True)
    try:
        while not stop.wait(CONTROL_POLL):
            if control is not None:
                control.poll()
    finally:
        relay.close()
    print(f"link_delay: closed after {relay.accepted} connection(s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
