"""The live view's front door (docs/ros2.md, "Live view"): a WebSocket acceptor that speaks both names of the Foxglove
WebSocket protocol and relays each connection to the foxglove-sdk server behind it.

foxglove-sdk (0.30) accepts only the subprotocol ``foxglove.sdk.v1``; Lichtblick and the published
``@foxglove/ws-protocol`` client offer only ``foxglove.websocket.v1``, the same protocol under its former name, and
get HTTP 400. The relay accepts either (a client offering both gets ``foxglove.sdk.v1``), opens its own connection to
the SDK server on loopback with ``foxglove.sdk.v1`` and copies every frame both ways unchanged, text and binary.
"""

from __future__ import annotations

import asyncio
import threading

from agents.errors import FleetError

#: The subprotocol foxglove-sdk speaks, and its former name (same messages).
SDK_SUBPROTOCOL = "foxglove.sdk.v1"
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"


class ViewRelayError(FleetError):
    """The relay could not listen where it was asked to."""


class SubprotocolRelay:
    """Listens on ``host:port`` (0: a free port) and relays each client to ``ws://127.0.0.1:<inner_port>``.

    Runs its own event loop in a daemon thread between :meth:`start` and :meth:`stop`.
    """

    def __init__(self, host: str, port: int, inner_port: int) -> None:
        self.host, self.port, self.inner_port = host, port, inner_port
        self.connections = 0
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopped: asyncio.Event | None = None
        self._error: BaseException | None = None

    def start(self) -> int:
        """Listen; return the port (raises :class:`ViewRelayError` when it cannot)."""
        ready = threading.Event()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._serve(ready)), name="view-relay",
                                        daemon=True)
        self._thread.start()
        ready.wait()
        if self._error is not None:
            raise ViewRelayError(f"cannot serve the view on {self.host}:{self.port}: {self._error}")
        return self.port

    def stop(self) -> None:
        if self._loop is not None and self._stopped is not None:
            self._loop.call_soon_threadsafe(self._stopped.set)
        if self._thread is not None:
            self._thread.join(5)

    async def _serve(self, ready: threading.Event) -> None:
        from websockets.asyncio.server import serve

        self._loop, self._stopped = asyncio.get_running_loop(), asyncio.Event()
        try:
            server = await serve(self._relay, self.host, self.port, max_size=None, compression=None,
                                 subprotocols=[SDK_SUBPROTOCOL, LEGACY_SUBPROTOCOL])
        except OSError as err:
            self._error = err
            ready.set()
            return
        async with server:
            self.port = server.sockets[0].getsockname()[1]
            ready.set()
            await self._stopped.wait()

    async def _relay(self, client) -> None:
        from websockets.asyncio.client import connect
        from websockets.exceptions import ConnectionClosed

        self.connections += 1
        async with connect(f"ws://127.0.0.1:{self.inner_port}", subprotocols=[SDK_SUBPROTOCOL], max_size=None,
                           compression=None, open_timeout=10) as upstream:
            async def copy(source, sink) -> None:
                try:
                    async for frame in source:
                        await sink.send(frame)
                except ConnectionClosed:
                    pass

            pumps = [asyncio.create_task(copy(client, upstream)), asyncio.create_task(copy(upstream, client))]
            _, pending = await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
            for task in pending:
                task.cancel()
