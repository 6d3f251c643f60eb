"""A tiny in-process ROS 1 master for the TCPROS tests: the part of the Master API a node uses.

It keeps publishers and subscribers per topic and, like roscore, tells a topic's subscribers the new
publisher list (``publisherUpdate``) whenever it changes. ``register_raw_publisher`` lets a test add a
hand-made publisher.
"""

from __future__ import annotations

import threading
import xmlrpc.client
from collections import defaultdict
from typing import Any
from xmlrpc.server import SimpleXMLRPCServer


def serve_master_api(master: Any, server: SimpleXMLRPCServer) -> threading.Thread:
    """``master``'s ``registerPublisher``/``registerSubscriber``, their ``unregister*`` and ``getUri`` (its ``uri``)
    answered by ``server`` from a started thread (the master's ``close`` shuts it down)."""
    for name in ("registerPublisher", "registerSubscriber", "unregisterPublisher", "unregisterSubscriber"):
        server.register_function(getattr(master, name), name)
    server.register_function(lambda caller: [1, "", master.uri], "getUri")
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05})
    thread.start()
    return thread


class FakeMaster:
    """``registerPublisher``/``registerSubscriber``, their ``unregister*`` and ``getUri``, on 127.0.0.1."""

    def __init__(self) -> None:
        self._server = SimpleXMLRPCServer(("127.0.0.1", 0), logRequests=False)
        self.publishers: defaultdict[str, list[str]] = defaultdict(list)
        self.subscribers: defaultdict[str, list[str]] = defaultdict(list)
        self._notifiers: list[threading.Thread] = []
        self.refuse: set[str] = set()  # topics whose registration fails (code -1), as a master's error
        self._thread = serve_master_api(self, self._server)

    @property
    def uri(self) -> str:
        return f"http://127.0.0.1:{self._server.server_address[1]}/"

    def registerPublisher(self, caller: str, topic: str, msgtype: str, api: str) -> list[Any]:
        if topic in self.refuse:
            return [-1, f"{topic} refused", []]
        self.publishers[topic].append(api)
        self._notify(topic)
        return [1, "", list(self.subscribers[topic])]

    def registerSubscriber(self, caller: str, topic: str, msgtype: str, api: str) -> list[Any]:
        if topic in self.refuse:
            return [-1, f"{topic} refused", []]
        self.subscribers[topic].append(api)
        return [1, "", list(self.publishers[topic])]

    def unregisterPublisher(self, caller: str, topic: str, api: str) -> list[Any]:
        self.publishers[topic].remove(api)
        self._notify(topic)
        return [1, "", 1]

    def unregisterSubscriber(self, caller: str, topic: str, api: str) -> list[Any]:
        self.subscribers[topic].remove(api)
        return [1, "", 1]

    def _notify(self, topic: str) -> None:
        publishers = list(self.publishers[topic])
        for api in self.subscribers[topic]:
            thread = threading.Thread(target=_publisher_update, args=(api, topic, publishers))
            self._notifiers.append(thread)
            thread.start()

    def close(self) -> None:
        for thread in self._notifiers:
            thread.join(5)
        self._server.shutdown()
        self._thread.join(5)
        self._server.server_close()


def _publisher_update(api: str, topic: str, publishers: list[str]) -> None:
    try:
        with xmlrpc.client.ServerProxy(api) as proxy:
            proxy.publisherUpdate("/master", topic, publishers)
    except OSError:
        pass  # the node has gone (roscore ignores this too)
