"""The graph's topics as Foxglove schema objects, served over WebSocket (the ``live_view`` node).

ROS-free: the messages come in as rclpy objects, but only their fields are read. What each
topic becomes (:data:`VIEWS`; channel: schema):

* ``nav/fix`` -> ``/nav/fix``: ``foxglove.LocationFix``, the Map panel's track, carrying the
  heading of the latest ``ins/state``; blue while a fix, red while NO_FIX (aligning, dead
  reckoning).
* ``gnss/fix`` -> ``/gnss/fix``: ``foxglove.LocationFix``, the receiver's track, orange.
* ``nav/odom`` -> ``/nav/odom``: ``foxglove.PoseInFrame`` in ``map`` (3D panel), and
  ``/nav/odom/tf``: ``foxglove.FrameTransform`` map -> base_link.
* ``ins/state`` -> ``/ins/state/attitude``: JSON, heading (azimuth from true north), pitch (nose
  up) and roll (right wing down) in degrees, speed, mode.
* ``nav/status`` -> ``/nav/status``: JSON, mode, coupling, counts, the updates, state sigmas.
* ``/diagnostics`` -> ``/diagnostics``: ``foxglove.Log``, one per status (Log panel).

Channel names are the resolved ROS names given to :class:`FoxgloveView`. A message is translated
only when a client subscribes to its channel (``has_sinks``): with no client a message costs a
dictionary look-up and one call into the SDK per channel. Messages are logged at their header
stamp (sensor time), so Foxglove's timeline is the graph's time axis.

The server offers no client capabilities (no publishing, parameters or services): a viewer can
only watch.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable

import foxglove
import numpy as np
from foxglove.channels import (FrameTransformChannel, LocationFixChannel, LogChannel,
                               PoseInFrameChannel)
from foxglove.messages import (Color, FrameTransform, KeyValuePair, LocationFix,
                               LocationFixPositionCovarianceType, Log, LogLevel, Pose,
                               PoseInFrame, Quaternion, Timestamp, Vector3)

from ..nav.conventions import seed_angles_from_quat
from .stamps import NS, msg_stamp_ns

#: NavSatFix.position_covariance_type (0..3) -> the Foxglove enum of the same meaning.
_COVARIANCE_TYPES = (LocationFixPositionCovarianceType.Unknown,
                     LocationFixPositionCovarianceType.Approximated,
                     LocationFixPositionCovarianceType.DiagonalKnown,
                     LocationFixPositionCovarianceType.Known)
#: NavSatStatus.STATUS_NO_FIX.
_NO_FIX = -1
_FIX_COLOR = Color(r=0.12, g=0.47, b=0.71, a=1.0)
_NO_FIX_COLOR = Color(r=0.84, g=0.15, b=0.16, a=1.0)
_RECEIVER_COLOR = Color(r=1.0, g=0.5, b=0.05, a=1.0)
#: DiagnosticStatus level (OK, WARN, ERROR, STALE) -> Log level; a stale input is a warning.
_LOG_LEVELS = (LogLevel.Info, LogLevel.Warning, LogLevel.Error, LogLevel.Warning)


def timestamp(t_ns: int) -> Timestamp:
    """Foxglove timestamp of integer ns."""
    sec, nsec = divmod(int(t_ns), NS)
    return Timestamp(sec, nsec)


@lru_cache(maxsize=None)
def _constant_names(cls, prefix: str) -> dict[int, str]:
    """{value: name} of a message class' constants ``PREFIX_NAME`` (FilterStatus.MODE_...)."""
    return {getattr(cls, n): n[len(prefix):] for n in dir(cls) if n.startswith(prefix)}


def _name(cls, prefix: str, value: int) -> str:
    return _constant_names(cls, prefix).get(value, str(value))


def _quaternion(q) -> Quaternion:
    return Quaternion(x=q.x, y=q.y, z=q.z, w=q.w)


def _vector(v) -> Vector3:
    return Vector3(x=v.x, y=v.y, z=v.z)


def _angles(state) -> tuple[float, float, float]:
    """(azimuth of the body x axis clockwise from true north, pitch nose up, roll right wing
    down), rad, of an InsState's orientation."""
    o = state.orientation
    return tuple(float(a) for a in seed_angles_from_quat(np.array([o.w, o.x, o.y, o.z])))


def location_fix(fix, color: Color, heading: float | None = None) -> LocationFix:
    """A NavSatFix (degrees, m, ENU covariance m^2) as a LocationFix, with ``heading`` (rad
    clockwise from true north: the Heading azimuth convention is Foxglove's too)."""
    return LocationFix(
        timestamp=timestamp(msg_stamp_ns(fix)), frame_id=fix.header.frame_id,
        latitude=fix.latitude, longitude=fix.longitude, altitude=fix.altitude,
        position_covariance=[float(c) for c in fix.position_covariance],
        position_covariance_type=_COVARIANCE_TYPES[fix.position_covariance_type],
        heading=heading, color=color,
        metadata=[KeyValuePair(key="status", value=str(fix.status.status))])


def pose_in_frame(odom) -> PoseInFrame:
    """nav/odom's pose in its frame (``map``, ENU)."""
    p = odom.pose.pose
    return PoseInFrame(timestamp=timestamp(msg_stamp_ns(odom)), frame_id=odom.header.frame_id,
                       pose=Pose(position=_vector(p.position),
                                 orientation=_quaternion(p.orientation)))


def frame_transform(odom) -> FrameTransform:
    """nav/odom as the transform header.frame_id -> child_frame_id (map -> base_link)."""
    p = odom.pose.pose
    return FrameTransform(timestamp=timestamp(msg_stamp_ns(odom)),
                          parent_frame_id=odom.header.frame_id,
                          child_frame_id=odom.child_frame_id,
                          translation=_vector(p.position),
                          rotation=_quaternion(p.orientation))


def attitude(state) -> dict:
    """An InsState's attitude as a navigator reads it (degrees), its speed and mode."""
    heading, pitch, roll = _angles(state)
    v = state.velocity
    return {"heading_deg": math.degrees(heading), "pitch_deg": math.degrees(pitch),
            "roll_deg": math.degrees(roll), "speed_mps": math.sqrt(v.x**2 + v.y**2 + v.z**2),
            "mode": _name(type(state), "MODE_", state.mode)}


ATTITUDE_SCHEMA = {
    "type": "object", "title": "ins_gnss_ros.Attitude",
    "properties": {
        "heading_deg": {"type": "number", "description": "azimuth of the body x axis, "
                        "clockwise from true north, deg"},
        "pitch_deg": {"type": "number", "description": "nose up positive, deg"},
        "roll_deg": {"type": "number", "description": "right wing down positive, deg"},
        "speed_mps": {"type": "number", "description": "|velocity|, m/s"},
        "mode": {"type": "string", "description": "InsState mode"},
    },
}


def filter_status(status) -> dict:
    """A FilterStatus: mode and coupling by name, the counts, the updates since the last
    status and the state standard deviations by state name."""
    cls = type(status)
    return {
        "mode": _name(cls, "MODE_", status.mode),
        "coupling": _name(cls, "COUPLING_", status.coupling),
        "accepted_count": int(status.accepted_count),
        "rejected_count": int(status.rejected_count),
        "updates": [{"name": u.name, "accepted": bool(u.accepted), "nis": float(u.nis),
                     "gate": float(u.gate), "reason": u.reason} for u in status.updates],
        "state_std": dict(zip(status.state_names, (float(s) for s in status.state_std))),
    }


FILTER_STATUS_SCHEMA = {
    "type": "object", "title": "ins_gnss_ros.FilterStatus",
    "properties": {
        "mode": {"type": "string"}, "coupling": {"type": "string"},
        "accepted_count": {"type": "integer"}, "rejected_count": {"type": "integer"},
        "updates": {"type": "array", "items": {"type": "object", "properties": {
            "name": {"type": "string"}, "accepted": {"type": "boolean"},
            "nis": {"type": "number"}, "gate": {"type": "number"},
            "reason": {"type": "string"}}}},
        "state_std": {"type": "object", "description": "state name -> sigma, SI units",
                      "additionalProperties": {"type": "number"}},
    },
}


def logs(array) -> list[Log]:
    """A DiagnosticArray as one Log per status: "message (key=value, ...)" at its level."""
    stamp = timestamp(msg_stamp_ns(array))
    out = []
    for s in array.status:
        level = s.level[0] if isinstance(s.level, bytes) else int(s.level)
        values = ", ".join(f"{kv.key}={kv.value}" for kv in s.values)
        out.append(Log(timestamp=stamp, level=_LOG_LEVELS[min(level, 3)], name=s.name,
                       message=f"{s.message} ({values})" if values else s.message))
    return out


@dataclass(frozen=True)
class View:
    """One Foxglove channel made from one ROS topic.

    ``make`` builds the channel (``make(name, context=...)``), ``translate`` the objects to log
    from a message (``translate(msg, view)``, a list: a DiagnosticArray gives one Log per
    status); ``suffix`` is appended to the ROS name for the channel's name.
    """
    topic: str
    msgtype: str
    make: Callable[[str, foxglove.Context], Any]
    translate: Callable[[Any, "FoxgloveView"], list]
    suffix: str = ""


def _json_channel(schema: dict):
    return lambda name, *, context: foxglove.Channel(name, schema=schema, context=context)


VIEWS = (
    View("nav/fix", "sensor_msgs/msg/NavSatFix", LocationFixChannel,
         lambda fix, view: [location_fix(
             fix, _NO_FIX_COLOR if fix.status.status == _NO_FIX else _FIX_COLOR,
             None if view.latest_state is None else _angles(view.latest_state)[0])]),
    View("gnss/fix", "sensor_msgs/msg/NavSatFix", LocationFixChannel,
         lambda fix, view: [location_fix(fix, _RECEIVER_COLOR)]),
    View("nav/odom", "nav_msgs/msg/Odometry", PoseInFrameChannel,
         lambda odom, view: [pose_in_frame(odom)]),
    View("nav/odom", "nav_msgs/msg/Odometry", FrameTransformChannel,
         lambda odom, view: [frame_transform(odom)], "/tf"),
    View("ins/state", "ins_gnss_msgs/msg/InsState", _json_channel(ATTITUDE_SCHEMA),
         lambda state, view: [attitude(state)], "/attitude"),
    View("nav/status", "ins_gnss_msgs/msg/FilterStatus", _json_channel(FILTER_STATUS_SCHEMA),
         lambda status, view: [filter_status(status)]),
    View("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", LogChannel,
         lambda array, view: logs(array)),
)


class ViewError(RuntimeError):
    """The WebSocket server could not start (address in use, bad host)."""


class FoxgloveView:
    """A Foxglove WebSocket server with one channel per :data:`VIEWS` entry.

    Parameters
    ----------
    names : dict of str to str
        Resolved ROS name of each view topic (``{"nav/fix": "/ns/nav/fix", ...}``).
    host, port : str, int
        Address to bind; port 0 takes a free one (:attr:`port` says which).
    name : str
        Server name shown by Foxglove.
    """

    def __init__(self, names: dict[str, str], host: str, port: int, name: str):
        # A context of its own: several views (tests, replays) in one process stay apart.
        self._context = foxglove.Context()
        self._channels: dict[str, list] = {}
        for view in VIEWS:
            channel = view.make(names[view.topic] + view.suffix, context=self._context)
            self._channels.setdefault(view.topic, []).append((channel, view.translate))
        self.latest_state = None  # the latest ins/state: nav/fix markers take its heading
        try:
            self._server = foxglove.start_server(name=name, host=host, port=port,
                                                 capabilities=[], context=self._context)
        except Exception as err:  # the SDK raises its own RuntimeError with the OS error
            raise ViewError(f"cannot serve on {host}:{port}: {err}") from None
        self.port = self._server.port

    def watched(self, topic: str) -> bool:
        """Does a client subscribe to a channel made from view topic ``topic``?"""
        return any(channel.has_sinks() for channel, _ in self._channels[topic])

    def forward(self, topic: str, msg) -> None:
        """Log ``msg`` of view topic ``topic`` on its channels that a client subscribes to."""
        if topic == "ins/state":
            self.latest_state = msg
        log_time = None
        for channel, translate in self._channels[topic]:
            if channel.has_sinks():
                if log_time is None:
                    log_time = msg_stamp_ns(msg)
                for obj in translate(msg, self):
                    channel.log(obj, log_time=log_time)

    def close(self) -> None:
        """Stop the server (clients are disconnected)."""
        self._server.stop()
