"""The ``ekf`` node's services, as robot_localization's and navsat_transform's: ``~/reset``
(std_srvs/Empty: align again from nothing), ``~/set_pose`` (navigate on from a map-frame pose:
:func:`ins_gnss_ros.nav.set_pose.set_pose`), ``~/set_datum``, ``~/to_ll`` and ``~/from_ll``
(:mod:`ins_gnss_ros.nav.local_frame`). A mixin of :class:`~.ekf_node.EkfNode`: the services act
on its navigator, aiding front end and strapdown synchronisation.
"""

from __future__ import annotations

import numpy as np
from ins_gnss_msgs.srv import FromLL, SetDatum, SetPose, ToLL
from std_srvs.srv import Empty

from ..io import stamp_to_sec
from ..nav.local_frame import datum_from_degrees, from_map, to_map
from ..nav.set_pose import set_pose
from .convert import quat


class EkfServices:
    def register_services(self) -> None:
        self.service(Empty, "~/reset", self.on_reset)
        self.service(SetPose, "~/set_pose", self.on_set_pose)
        self.service(SetDatum, "~/set_datum", self.on_set_datum)
        self.service(ToLL, "~/to_ll", self.on_to_ll)
        self.service(FromLL, "~/from_ll", self.on_from_ll)

    def on_reset(self, request, response):
        """Forget everything: the filter aligns again (the datum stays)."""
        self.navigator.reset()
        self.sync.invalidate()  # the strapdown's states are not the solution until re-synced
        self.get_logger().info("reset: aligning again")
        return response

    def on_set_pose(self, request: SetPose.Request, response: SetPose.Response):
        pose = request.pose
        if pose.header.frame_id not in ("", self.p["map_frame"]):
            response.message = f"pose in frame {pose.header.frame_id!r}, not {self.p['map_frame']!r}"
            return response
        if self.aiding.datum is None:
            response.message = "no datum yet: set one (~/set_datum) or wait for a fix"
            return response
        p, q = pose.pose.pose.position, quat(pose.pose.pose.orientation)
        norm = np.linalg.norm(q)
        if not (np.isfinite([p.x, p.y, p.z]).all() and np.isfinite(norm) and norm > 0.5):
            response.message = "pose not finite or its quaternion not a rotation"
            return response
        lat, lon, h = from_map(self.aiding.datum, (p.x, p.y, p.z))
        set_pose(self.navigator, stamp_to_sec(pose.header.stamp), lat, lon, h, q / norm,
                 np.reshape(pose.pose.covariance, (6, 6)))
        self.sync.invalidate()
        self.converging = True
        self.after_filter()
        response.success, response.message = True, "navigating from the pose"
        return response

    def on_set_datum(self, request: SetDatum.Request, response: SetDatum.Response):
        try:
            self.aiding.datum = datum_from_degrees(request.latitude, request.longitude,
                                                   request.altitude)
        except ValueError as err:
            response.message = str(err)
            return response
        self.note_datum(self.now_msg())
        response.success, response.message = True, "datum set"
        return response

    def on_to_ll(self, request: ToLL.Request, response: ToLL.Response):
        if self.aiding.datum is None:
            response.message = "no datum yet"
            return response
        p = request.map_point
        lat, lon, response.altitude = from_map(self.aiding.datum, (p.x, p.y, p.z))
        response.latitude, response.longitude = float(np.degrees(lat)), float(np.degrees(lon))
        response.success = True
        return response

    def on_from_ll(self, request: FromLL.Request, response: FromLL.Response):
        if self.aiding.datum is None:
            response.message = "no datum yet"
            return response
        p = response.map_point
        p.x, p.y, p.z = (float(v) for v in to_map(
            self.aiding.datum, np.radians(request.latitude), np.radians(request.longitude),
            request.altitude))
        response.success = True
        return response
