"""A loopback TCP forwarder that can cut the board link on demand (tests, mm-bench agent).

The node connects to the proxy, the proxy to the agent. :meth:`DropProxy.cut`
closes every forwarded connection and refuses new ones until :meth:`restore`:
to the node and the agent that is a real link drop (the peer's socket closes),
not a paused process. :meth:`DropProxy.flap` is a link that drops again a moment
after it came back.
"""

from __future__ import annotations

import contextlib
import socket
import threading


class DropProxy:
    def __init__(self, target_port: int, host: str = "127.0.0.1") -> None:
        self.target = (host, target_port)
        self.listener = socket.create_server((host, 0))
        self.port = self.listener.getsockname()[1]
        self.endpoint = f"tcp/{host}:{self.port}"
        self._open = True
        self._conns: list[socket.socket] = []
        self._lock = threading.Lock()
        self._running = True
        self._connected = threading.Event()  # set at each forwarded connection
        threading.Thread(target=self._accept, name="drop_proxy", daemon=True).start()

    def _accept(self) -> None:
        while self._running:
            try:
                client, _ = self.listener.accept()
            except OSError:
                return
            if not self._open:
                client.close()
                continue
            try:
                upstream = socket.create_connection(self.target, timeout=2)
            except OSError:
                client.close()
                continue
            upstream.settimeout(None)
            with self._lock:
                if not self._open:  # cut while we connected
                    client.close()
                    upstream.close()
                    continue
                self._conns += [client, upstream]
            self._connected.set()
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pipe, args=(a, b), daemon=True).start()

    @staticmethod
    def _pipe(src: socket.socket, dst: socket.socket) -> None:
        try:
            while data := src.recv(65536):
                dst.sendall(data)
        except OSError:
            pass
        for s in (src, dst):
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)

    def cut(self) -> None:
        """Drop every forwarded connection; refuse new ones until :meth:`restore`."""
        with self._lock:
            self._open = False
            conns, self._conns = self._conns, []
        for s in conns:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()

    def restore(self) -> None:
        self._open = True

    def flap(self, up_s: float, down_s: float, timeout: float = 30.0) -> bool:
        """A link that comes back and drops again: restore, wait for the next
        connection, let it live ``up_s`` seconds, cut for ``down_s``, restore.
        False if nobody connected within ``timeout`` (the link stays restored)."""
        self._connected.clear()
        self.restore()
        if not self._connected.wait(timeout):
            return False
        threading.Event().wait(up_s)
        self.cut()
        threading.Event().wait(down_s)
        self.restore()
        return True

    def close(self) -> None:
        self._running = False
        self.cut()
        self.listener.close()


class ProxyProcess:
    """A :class:`DropProxy` in a process of its own (no GIL shared with the test's rclpy).

    Same ``endpoint``, ``cut``, ``restore`` and ``close``; controlled over stdin.
    """

    def __init__(self, target_port: int) -> None:
        import subprocess
        import sys

        self.proc = subprocess.Popen(
            [sys.executable, "-m", "mm_beagle.tools.link_proxy", str(target_port)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self.endpoint = self.proc.stdout.readline().strip()

    def _say(self, what: str) -> None:
        self.proc.stdin.write(what + "\n")
        self.proc.stdin.flush()
        self.proc.stdout.readline()  # "ok": done

    def cut(self) -> None:
        self._say("cut")

    def restore(self) -> None:
        self._say("restore")

    def flap(self, up_s: float, down_s: float) -> None:
        self._say(f"flap {up_s} {down_s}")

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(5)


def _main() -> None:
    import sys

    proxy = DropProxy(int(sys.argv[1]))
    print(proxy.endpoint, flush=True)
    for line in sys.stdin:
        words = line.split()
        if words == ["cut"]:
            proxy.cut()
        elif words == ["restore"]:
            proxy.restore()
        elif len(words) == 3 and words[0] == "flap":
            proxy.flap(float(words[1]), float(words[2]))
        print("ok", flush=True)
    proxy.close()


if __name__ == "__main__":
    _main()
