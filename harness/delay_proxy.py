"""A TCP proxy that delays every byte towards the server by a fixed time: a slow companion for the tests.

Put in front of a companion's control surface (register the vehicle's control URL as the proxy's), each
HTTP request reaches the companion ``delay_s`` late, in order (a latency, not a throughput limit: bytes
sent meanwhile are delayed by the same time, not queued behind each other); the answers come back at once.
Runs its own asyncio loop in a daemon thread on a free loopback port.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import threading
import time

from taskflight_common.ports import free_ports


class DelayProxy:
    """``127.0.0.1:port`` -> ``target_host:target_port``, client-to-server bytes ``delay_s`` late."""

    def __init__(self, target_host: str, target_port: int, delay_s: float) -> None:
        self.target, self.delay_s = (target_host, target_port), delay_s
        self.port = free_ports(1, socket.SOCK_STREAM)[0]
        self.url = f"http://127.0.0.1:{self.port}"
        self.requests = 0
        self._tasks: set[asyncio.Task[None]] = set()  # held: a pending task only weakly held may be collected
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._server: asyncio.Server | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        if not self._ready.wait(10):
            raise RuntimeError("the delay proxy did not start")

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        self._server = self._loop.run_until_complete(
            asyncio.start_server(self._serve, "127.0.0.1", self.port))
        self._ready.set()
        self._loop.run_forever()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        me = asyncio.current_task()
        if me is not None:
            self._tasks.add(me)
            me.add_done_callback(self._tasks.discard)
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.target)
        except OSError:
            writer.close()
            return
        pending: asyncio.Queue[tuple[float, bytes]] = asyncio.Queue()

        async def client_to_server() -> None:
            while data := await reader.read(65536):
                self.requests += data.count(b"HTTP/1.1\r\n")
                pending.put_nowait((time.monotonic() + self.delay_s, data))
            pending.put_nowait((time.monotonic() + self.delay_s, b""))

        async def delayed_writer() -> None:
            while True:
                due, data = await pending.get()
                await asyncio.sleep(max(0.0, due - time.monotonic()))
                if not data:
                    up_writer.write_eof()
                    return
                up_writer.write(data)
                await up_writer.drain()

        async def server_to_client() -> None:
            while data := await up_reader.read(65536):
                writer.write(data)
                await writer.drain()
            writer.close()

        tasks = [asyncio.create_task(c()) for c in (client_to_server, delayed_writer, server_to_client)]
        for t in tasks:
            self._tasks.add(t)
            t.add_done_callback(self._tasks.discard)
        with contextlib.suppress(Exception):
            await asyncio.wait(tasks, return_when=asyncio.FIRST_EXCEPTION)
            await tasks[2]
        for t in tasks:
            t.cancel()
        for w in (writer, up_writer):
            with contextlib.suppress(Exception):
                w.close()

    def close(self) -> None:
        def stop() -> None:
            if self._server is not None:
                self._server.close()
            for t in list(self._tasks):
                t.cancel()
            self._loop.call_later(0.1, self._loop.stop)
        self._loop.call_soon_threadsafe(stop)
        self._thread.join(10)
