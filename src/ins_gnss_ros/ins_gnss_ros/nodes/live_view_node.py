"""``live_view`` node: the graph's topics served to Foxglove over WebSocket (docs/VIEWING.md).

Subscribes ``nav/fix``, ``gnss/fix``, ``nav/odom``, ``ins/state``, ``nav/status`` and
``/diagnostics`` and hands every message to a
:class:`~ins_gnss_ros.io.foxglove_view.FoxgloveView`, which translates it into Foxglove schemas
(the Map panel's geo-located track, poses, attitude, filter mode, logs) only while a client
watches. Best-effort subscriptions: a slow viewer never holds back the navigation graph.

The server binds 127.0.0.1 by default (this machine only); ``host`` opens it to a network. It
accepts no data, parameters or service calls from clients.
"""

from __future__ import annotations

from ..io import msg_class
from ..io.foxglove_view import VIEWS, FoxgloveView, ViewError
from .base import DRIVER_QOS, NavNode, Param, ParameterError, run


class LiveViewNode(NavNode):
    PARAMS = (
        Param("host", "127.0.0.1",
              "address the WebSocket server binds: 127.0.0.1 serves this machine only, 0.0.0.0 "
              "every interface (unauthenticated, unencrypted: a trusted network only)"),
        Param("port", 8765, "WebSocket port (Foxglove's default 8765); 0: any free port, logged",
              0, 65535),
    )

    def __init__(self, **kwargs):
        super().__init__("live_view", **kwargs)
        topics = {view.topic: view.msgtype for view in VIEWS}
        names = {topic: self.resolve_topic_name(topic) for topic in topics}
        try:
            self.view = FoxgloveView(names, self.p["host"], self.p["port"],
                                     self.get_fully_qualified_name())
        except ViewError as err:
            raise ParameterError(str(err)) from None
        self.url = f"ws://{self.p['host']}:{self.view.port}"
        self.diag.set_value("url", self.url)
        self.get_logger().info(f"Foxglove live view on {self.url}")
        if self.p["host"] not in ("127.0.0.1", "localhost", "::1"):
            self.get_logger().warning(f"live view open to the network on {self.p['host']}: "
                                      "anyone who reaches it sees the navigation solution")
        for topic, msgtype in topics.items():
            self.subscribe(msg_class(msgtype), topic, self._forwarder(topic), DRIVER_QOS)

    def _forwarder(self, topic: str):
        def forward(msg) -> None:
            try:
                self.view.forward(topic, msg)
            except (ValueError, IndexError, TypeError, OverflowError) as err:
                self.diag.count(f"{topic}: not translatable ({type(err).__name__})")
        return forward

    def destroy_node(self):
        self.view.close()
        return super().destroy_node()


def main(args=None):
    return run(LiveViewNode, args)
