"""The delaying TCP relay (tooling.link_delay), on loopback only: an echo server upstream."""
import hashlib
import os
import random
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from tooling.link_delay import DelayRelay, main

TESTS = Path(__file__).resolve().parent     # where python -m tooling.link_delay runs


class EchoServer:
    """Echoes every byte back on 127.0.0.1; a connection ends when its client half-closes."""

    def __init__(self):
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.address = self.sock.getsockname()
        self.threads: list[threading.Thread] = []
        self._accept = threading.Thread(target=self._serve, daemon=True)
        self._accept.start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            t = threading.Thread(target=self._echo, args=(conn,), daemon=True)
            t.start()
            self.threads.append(t)

    @staticmethod
    def _echo(conn: socket.socket) -> None:
        with conn:
            try:
                while data := conn.recv(65536):
                    conn.sendall(data)
            except OSError:
                pass

    def close(self) -> None:
        self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
        self._accept.join(5)
        for t in self.threads:
            t.join(5)


@pytest.fixture
def echo():
    server = EchoServer()
    yield server
    server.close()


def round_trip(conn: socket.socket, size: int = 64) -> float:
    """Seconds for ``size`` bytes to come back."""
    payload = os.urandom(size)
    t0 = time.monotonic()
    conn.sendall(payload)
    got = b""
    while len(got) < size:
        chunk = conn.recv(65536)
        assert chunk, "connection closed"
        got += chunk
    rtt = time.monotonic() - t0
    assert got == payload
    return rtt


def median_rtt(conn: socket.socket, n: int = 5) -> float:
    return statistics.median(round_trip(conn) for _ in range(n))


def fds() -> set[tuple[str, str]]:
    """This process's open file descriptors (number, target), without the listing's own."""
    out = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            out.add((fd, os.readlink(f"/proc/self/fd/{fd}")))
        except OSError:                 # the directory listing itself, closed by now
            pass
    return out


def bound(relay: DelayRelay) -> tuple[str, int]:
    """The address ``relay`` listens on, once started."""
    assert relay.address is not None, "relay not started"
    return relay.address


def wait_until(cond, timeout: float = 5.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.02)
    return cond()


def test_round_trip_grows_by_twice_the_one_way_delay(echo):
    with DelayRelay(("127.0.0.1", 0), echo.address, delay=0.0) as relay, \
            socket.create_connection(bound(relay), timeout=10) as conn:
        base = median_rtt(conn)
        assert base < 0.05
        relay.set_delay(0.1)
        delayed = median_rtt(conn)
    # one-way 100 ms each way: +200 ms (generous upper margin for a busy machine)
    assert 0.19 <= delayed - base <= 0.3, (base, delayed)


def test_data_intact_and_in_order_on_concurrent_connections(echo):
    """Three connections stream 1 MB each in random-sized writes, read concurrently."""
    rng = random.Random(7)
    blobs = [rng.randbytes(1_000_000) for _ in range(3)]
    results: dict[int, bytes] = {}

    def stream(k: int, address) -> None:
        with socket.create_connection(address, timeout=20) as conn:
            def send() -> None:
                data, i = blobs[k], 0
                while i < len(data):
                    n = rng.randint(1, 40_000)
                    conn.sendall(data[i:i + n])
                    i += n
                conn.shutdown(socket.SHUT_WR)       # half-close: the echo ends, then EOF
            sender = threading.Thread(target=send)
            sender.start()
            got = bytearray()
            while chunk := conn.recv(65536):
                got += chunk
            sender.join()
            results[k] = bytes(got)

    with DelayRelay(("127.0.0.1", 0), echo.address, delay=0.02) as relay:
        threads = [threading.Thread(target=stream, args=(k, relay.address)) for k in range(3)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        assert relay.accepted == 3
    for k in range(3):
        assert hashlib.sha256(results[k]).hexdigest() == hashlib.sha256(blobs[k]).hexdigest()


def test_delay_changes_at_run_time(echo):
    """0 -> 150 ms -> 0 on one open connection; bytes are never reordered."""
    with DelayRelay(("127.0.0.1", 0), echo.address) as relay, \
            socket.create_connection(bound(relay), timeout=10) as conn:
        assert median_rtt(conn) < 0.05
        relay.set_delay(0.15)
        assert relay.delay == 0.15
        assert 0.29 <= median_rtt(conn) <= 0.45
        # bytes sent under the delay, then the delay dropped: they still come back first
        conn.sendall(b"held")
        relay.set_delay(0.0)
        conn.sendall(b"-new")
        got = b""
        while len(got) < 8:
            got += conn.recv(64)
        assert got == b"held-new"
        assert median_rtt(conn) < 0.05


def test_close_leaves_no_thread_or_socket(echo):
    before_fds, before_threads = fds(), set(threading.enumerate())
    relay = DelayRelay(("127.0.0.1", 0), echo.address, delay=0.05).start()
    conn = socket.create_connection(bound(relay), timeout=10)
    round_trip(conn)
    conn.sendall(b"in flight")                  # held in the relay when it closes
    assert any(t.name.startswith("link-delay") for t in threading.enumerate())
    relay.close()
    assert conn.recv(64) == b""                 # the relay closed our connection
    conn.close()
    relay.close()                               # closing twice is harmless
    echo_threads = set(echo.threads)
    assert wait_until(lambda: not any(t.is_alive() for t in echo_threads))
    assert wait_until(lambda: fds() <= before_fds), fds() - before_fds
    assert set(threading.enumerate()) - before_threads - echo_threads == set()
    with pytest.raises(OSError):                # nobody listens there any more
        socket.create_connection(bound(relay), timeout=2).close()


def test_unreachable_upstream_closes_the_client(echo):
    with socket.create_server(("127.0.0.1", 0)) as s:
        dead = s.getsockname()                  # a port nobody listens on once closed
    with DelayRelay(("127.0.0.1", 0), dead) as relay, \
            socket.create_connection(bound(relay), timeout=5) as conn:
        try:
            assert conn.recv(16) == b""
        except ConnectionResetError:
            pass


def test_bad_arguments_say_what_is_wrong(capsys, echo):
    for argv, words in (
            (["--listen", "127.0.0.1", "--upstream", "127.0.0.1:1"], "--listen"),
            (["--listen", "127.0.0.1:0", "--upstream", "127.0.0.1:0"], "--upstream"),
            (["--listen", "127.0.0.1:0", "--upstream", "127.0.0.1:99999"], "--upstream"),
            (["--listen", "127.0.0.1:0", "--upstream", "127.0.0.1:1", "--delay-ms", "-5"],
             "--delay-ms"),
            (["--listen", "127.0.0.1:0", "--upstream", "127.0.0.1:1", "--delay-ms", "nan"],
             "--delay-ms"),
            (["--upstream", "127.0.0.1:1"], "--listen")):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert words in err and "error" in err, err
    with pytest.raises(ValueError, match="delay"):
        DelayRelay(("127.0.0.1", 0), echo.address, delay=-1.0)
    # the listen port is taken: a clear error, exit status 1
    host, port = echo.address
    assert main(["--listen", f"{host}:{port}", "--upstream", f"{host}:{port}"]) == 1
    assert "cannot listen on" in capsys.readouterr().err


def test_command_line_with_control_file(echo, tmp_path):
    """python -m tooling.link_delay: the printed address, the delay changed through the control
    file, a clean exit on SIGINT."""
    control = tmp_path / "delay_ms"
    proc = subprocess.Popen(
        [sys.executable, "-m", "tooling.link_delay", "--listen", "127.0.0.1:0", "--upstream",
         f"{echo.address[0]}:{echo.address[1]}", "--delay-ms", "0", "--control", str(control)],
        cwd=TESTS, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stderr is not None
        line = proc.stdout.readline()
        assert "relaying 127.0.0.1:" in line, line + proc.stderr.read()
        port = int(line.split("relaying 127.0.0.1:")[1].split()[0])
        with socket.create_connection(("127.0.0.1", port), timeout=10) as conn:
            assert median_rtt(conn) < 0.05
            tmp = tmp_path / "delay_ms.tmp"
            tmp.write_text("100\n")
            tmp.replace(control)
            assert "one-way delay now 100 ms" in proc.stdout.readline()
            assert 0.19 <= median_rtt(conn) <= 0.35
            control.write_text("fast please")   # refused: the delay stays
            time.sleep(0.2)
            assert 0.19 <= median_rtt(conn, 3) <= 0.35
            control.write_text("0")
            assert "one-way delay now 0 ms" in proc.stdout.readline()
            assert median_rtt(conn) < 0.05
            proc.send_signal(signal.SIGINT)
            assert proc.wait(timeout=10) == 0
            assert conn.recv(16) == b""
        out, err = proc.communicate(timeout=5)
        assert "closed after 1 connection(s)" in out
        assert "fast please" in err and "delay stays 100 ms" in err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
