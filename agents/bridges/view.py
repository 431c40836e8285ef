"""``evopose view``: a live Foxglove view of a fleet over a foxglove-sdk WebSocket server (docs/ros2.md, "Live view").

The SDK server listens on loopback; clients connect to :class:`agents.bridges.view_relay.SubprotocolRelay`, which
accepts both ``foxglove.sdk.v1`` and ``foxglove.websocket.v1`` (Lichtblick, ``@foxglove/ws-protocol``).

Channels (open ``docs/foxglove-layout.json`` in Foxglove for the panels):

- ``/tf`` (foxglove.FrameTransforms): ``map -> <V>/base_link -> <V>/camera_optical``, ``map -> <V>/target_estimate``,
  ``map -> <T>/truth``;
- ``/scene`` (foxglove.SceneUpdate): the target model at each estimate and (translucent) at the truth; each camera's
  frustum;
- ``/<V>/camera_calibration`` (foxglove.CameraCalibration): each camera's intrinsics, in its optical frame;
- ``/<V>/image`` (foxglove.CompressedImage): the shared image, else a blank canvas of the camera's size;
- ``/<V>/features`` (foxglove.ImageAnnotations): the feature points (green), the model projected at V's estimate
  (red) and at the truth (blue);
- ``/metrics`` (JSON, schema ``evopose.Metrics``, :data:`METRICS_SCHEMA`): per estimate: its time (Foxglove's
  ``{sec, nsec}``), vehicle, fitness, mismatch, converged, good, generations and, once a truth is known
  (``has_truth``), position and rotation error to it.

``/tf`` and ``/scene`` are coalesced to at most :data:`VIEW_RATE_HZ` messages a second (:meth:`FleetView.flush`); the
camera channels carry one message per shared frame, ``/metrics`` one per estimate.

Vehicle names and frames follow :mod:`agents.bridges.names`. Errors are against the truth of the same stamp (else the
newest), without the model's symmetries.
"""

from __future__ import annotations

import json
import threading
import time
from collections import OrderedDict
from collections.abc import Callable

import numpy as np

from protocol.codec import decode_sample
from protocol.errors import ProtocolError
from protocol.messages import FeatureSet, ImageFrame, PoseEstimate

from agents.bridges import names
from agents.bridges.mirror import observer_options
from agents.bridges.ros_msgs import camera_rig, quaternion_from_matrix, quaternion_from_rpy
from agents.bridges.tap import FleetTap, RawSample
from agents.bridges.translate import is_truth
from agents.bridges.view_scene import blank_png, frustum_lines, mesh_triangles, pose_errors, project
from agents.transport.session import SessionOptions, open_session

#: The name of the /metrics JSON schema (every channel's schema has a name: Foxglove and Lichtblick show it).
METRICS_SCHEMA_NAME = "evopose.Metrics"
#: Foxglove's time type in a JSON schema (what its own schemas, e.g. foxglove.Log, declare): seconds and nanoseconds
#: since the epoch, each an integer a JavaScript number holds exactly (a nanosecond count since 1970 does not).
TIME_SCHEMA = {
    "type": "object", "title": "time",
    "properties": {"sec": {"type": "integer", "minimum": 0, "maximum": 2**32 - 1},
                   "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}},
    "required": ["sec", "nsec"],
}
#: One plain type per field: Lichtblick's and Foxglove's JSON-schema parsers accept no type unions. The errors to the
#: truth are left out while there is no truth to compare with (``has_truth`` false), never null.
METRICS_SCHEMA = {
    "title": METRICS_SCHEMA_NAME,
    "type": "object",
    "properties": {
        "timestamp": TIME_SCHEMA, "vehicle": {"type": "string"}, "fitness": {"type": "number"},
        "mismatch": {"type": "number"}, "converged": {"type": "boolean"}, "good": {"type": "boolean"},
        "generations": {"type": "integer", "minimum": 0, "maximum": 2**32 - 1},
        "has_truth": {"type": "boolean"}, "error_position_m": {"type": "number"},
        "error_rotation_deg": {"type": "number"},
    },
    "required": ["timestamp", "vehicle", "fitness", "mismatch", "converged", "good", "generations",
                 "has_truth"],
}
#: /tf and /scene are coalesced: what arrived since the last flush goes out as one message (the newest transform per
#: child frame, the newest entity per id), at most this often. Viewers warn above 60 Hz; frames of several vehicles
#: arrive together (~50 messages/s each for a team of three at 10 frames/s).
VIEW_RATE_HZ = 25.0


def time_of(stamp_ns: int) -> dict:
    """A nanosecond stamp as Foxglove's ``{sec, nsec}``."""
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


#: Truth poses kept to pair estimates by stamp.
TRUTH_KEPT = 256


class FleetView:
    """Turns fleet samples into Foxglove messages on channels of ``context`` (one worker thread calls ``handle``)."""

    def __init__(self, context, model=None) -> None:
        import foxglove
        from foxglove import channels

        self._fg, self._ch, self.context, self.model = foxglove, channels, context, model
        self.tf = channels.FrameTransformsChannel("/tf", context=context)
        self.scene = channels.SceneUpdateChannel("/scene", context=context)
        self.metrics = foxglove.Channel("/metrics", schema=foxglove.Schema(
            name=METRICS_SCHEMA_NAME, encoding="jsonschema", data=json.dumps(METRICS_SCHEMA).encode()),
            message_encoding="json", context=context)
        self._cameras: dict[str, tuple] = {}
        self._estimates: dict[str, tuple[float, ...]] = {}
        self._truth: OrderedDict[int, tuple[float, ...]] = OrderedDict()
        self._pending_tf: dict[str, object] = {}
        self._pending_entities: dict[str, object] = {}
        self._lock = threading.Lock()
        self.logged = 0
        if model is not None:
            self._triangles = mesh_triangles(model.body.vertices, model.body.faces, model.body.colours)

    # -- helpers -----------------------------------------------------------------------------------

    def _m(self):
        from foxglove import messages

        return messages

    def _stamp(self, stamp_ns: int):
        return self._m().Timestamp(*divmod(int(stamp_ns), 1_000_000_000))

    def _transform(self, parent: str, child: str, stamp_ns: int, translation, quaternion):
        m = self._m()
        return m.FrameTransform(timestamp=self._stamp(stamp_ns), parent_frame_id=parent, child_frame_id=child,
                                translation=m.Vector3(**dict(zip("xyz", map(float, translation)))),
                                rotation=m.Quaternion(**dict(zip("xyzw", map(float, quaternion)))))

    def _camera_channels(self, vehicle: str) -> tuple:
        found = self._cameras.get(vehicle)
        if found is None:
            name, ch = names.ros_name(vehicle), self._ch
            found = self._cameras[vehicle] = (
                ch.CameraCalibrationChannel(f"/{name}/camera_calibration", context=self.context),
                ch.CompressedImageChannel(f"/{name}/image", context=self.context),
                ch.ImageAnnotationsChannel(f"/{name}/features", context=self.context))
        return found

    def _log(self, channel, message) -> None:
        channel.log(message)
        self.logged += 1

    def _send_tf(self, *transforms: tuple[str, object]) -> None:
        """Queue ``(child frame, FrameTransform)`` pairs for the next :meth:`flush` (the newest per child)."""
        with self._lock:
            self._pending_tf.update(transforms)

    def _send_entity(self, entity_id: str, entity) -> None:
        with self._lock:
            self._pending_entities[entity_id] = entity

    def flush(self) -> None:
        """Send what /tf and /scene gathered since the last flush, one message each (called every
        1 / :data:`VIEW_RATE_HZ` s)."""
        with self._lock:
            transforms, self._pending_tf = list(self._pending_tf.values()), {}
            entities, self._pending_entities = list(self._pending_entities.values()), {}
        if transforms:
            self._log(self.tf, self._m().FrameTransforms(transforms=transforms))
        if entities:
            self._log(self.scene, self._m().SceneUpdate(entities=entities))

    def _model_entity(self, entity_id: str, frame: str, stamp_ns: int, alpha: float):
        m = self._m()
        triangles, spheres = [], []
        if self.model is not None:
            points, rgba = self._triangles
            triangles = [m.TriangleListPrimitive(
                points=[m.Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in points],
                colors=[m.Color(r=r, g=g, b=b, a=alpha) for r, g, b, _ in rgba])]
            size = 2 * self.model.mark_radius
            for point, colour in zip(self.model.mark_points, self.model.mark_colours):
                bgr = self.model.palette[colour]
                spheres.append(m.SpherePrimitive(
                    pose=m.Pose(position=m.Vector3(**dict(zip("xyz", map(float, point)))),
                                orientation=m.Quaternion(w=1.0)),
                    size=m.Vector3(x=size, y=size, z=size), color=m.Color(r=bgr[2] / 255, g=bgr[1] / 255,
                                                                           b=bgr[0] / 255, a=alpha)))
        return m.SceneEntity(timestamp=self._stamp(stamp_ns), frame_id=frame, id=entity_id, frame_locked=True,
                             triangles=triangles, spheres=spheres)

    # -- messages ----------------------------------------------------------------------------------

    def handle(self, raw: RawSample) -> None:
        try:
            key, message = decode_sample(raw.key, raw.payload)
        except ProtocolError:
            return
        if isinstance(message, PoseEstimate):
            self._pose(key.vehicle, message)
        elif isinstance(message, (FeatureSet, ImageFrame)):
            self._camera(key.vehicle, message)

    def _pose(self, vehicle: str, message: PoseEstimate) -> None:
        pose, stamp = tuple(message.pose), message.stamp_ns
        q = quaternion_from_rpy(*pose[3:])
        if is_truth(message):
            self._truth[stamp] = pose
            while len(self._truth) > TRUTH_KEPT:
                self._truth.popitem(last=False)
            frame = names.truth_frame(vehicle)
            self._send_tf((frame, self._transform(names.MAP_FRAME, frame, stamp, pose[:3], q)))
            self._send_entity("truth", self._model_entity("truth", frame, stamp, 0.35))
            return
        self._estimates[vehicle] = pose
        frame = names.estimate_frame(vehicle)
        entity_id = f"estimate/{names.ros_name(vehicle)}"
        self._send_tf((frame, self._transform(names.MAP_FRAME, frame, stamp, pose[:3], q)))
        self._send_entity(entity_id, self._model_entity(entity_id, frame, stamp, 1.0))
        truth = self._truth.get(stamp) or (next(reversed(self._truth.values())) if self._truth else None)
        self._log(self.metrics, metrics_message(names.ros_name(vehicle), message,
                                                pose_errors(pose, truth) if truth is not None else None))

    def _camera(self, vehicle: str, message: FeatureSet | ImageFrame) -> None:
        m, stamp, camera = self._m(), message.stamp_ns, message.camera
        calibration, image, features = self._camera_channels(vehicle)
        base, optical = names.base_frame(vehicle), names.camera_frame(vehicle)
        position, r_world_base, r_base_camera = camera_rig(camera.world_from_camera)
        self._send_tf((base, self._transform(names.MAP_FRAME, base, stamp, position,
                                             quaternion_from_matrix(r_world_base))),
                      (optical, self._transform(base, optical, stamp, (0, 0, 0), quaternion_from_matrix(r_base_camera))))
        k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
        self._log(calibration, m.CameraCalibration(
            timestamp=self._stamp(stamp), frame_id=optical, width=camera.width, height=camera.height,
            distortion_model="plumb_bob", D=list(camera.distortion), K=k, R=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
            P=[camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0]))
        self._log(image, m.CompressedImage(timestamp=self._stamp(stamp), frame_id=optical, **self._image(message)))
        target = self._estimates.get(vehicle) or (next(reversed(self._truth.values())) if self._truth else None)
        depth = float(np.linalg.norm(np.subtract(target[:3], position))) if target is not None else 2.0
        lines = frustum_lines(camera, depth)
        frustum = f"frustum/{names.ros_name(vehicle)}"
        self._send_entity(frustum, m.SceneEntity(
            timestamp=self._stamp(stamp), frame_id=optical, id=frustum,
            frame_locked=True, lines=[m.LinePrimitive(
                type=m.LinePrimitiveLineType.LineList, thickness=2.0, scale_invariant=True,
                points=[m.Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in lines],
                color=m.Color(r=1.0, g=0.8, b=0.2, a=1.0))]))
        self._log(features, m.ImageAnnotations(points=self._annotations(vehicle, message, stamp)))

    def _image(self, message: FeatureSet | ImageFrame) -> dict:
        if isinstance(message, ImageFrame) and message.encoding in ("jpeg", "png"):
            return {"format": message.encoding, "data": message.data}
        if isinstance(message, ImageFrame):
            import cv2

            return {"format": "png", "data": cv2.imencode(".png", message.to_array())[1].tobytes()}
        return {"format": "png", "data": blank_png(message.camera.width, message.camera.height)}

    def _annotations(self, vehicle: str, message: FeatureSet | ImageFrame, stamp: int) -> list:
        m = self._m()
        sets = []
        if isinstance(message, FeatureSet):
            sets.append((message.points_uv, m.Color(r=0.2, g=1.0, b=0.2, a=1.0), 4.0))
        if self.model is not None:
            for pose, colour in ((self._estimates.get(vehicle), m.Color(r=1.0, g=0.2, b=0.2, a=1.0)),
                                 (self._truth.get(stamp), m.Color(r=0.3, g=0.5, b=1.0, a=1.0))):
                if pose is not None:
                    sets.append((project(self.model.mark_points, pose, message.camera), colour, 8.0))
        return [m.PointsAnnotation(timestamp=self._stamp(stamp), type=m.PointsAnnotationType.Points,
                                   points=[m.Point2(x=float(u), y=float(v)) for u, v in uv], outline_color=colour,
                                   fill_color=colour, thickness=size) for uv, colour, size in sets]


def metrics_message(vehicle: str, message: PoseEstimate, errors: tuple[float, float] | None) -> dict:
    """The /metrics message of an estimate (:data:`METRICS_SCHEMA`); ``errors``: (position m, rotation deg) to the
    truth, None without one; a non-finite error is left out, as JSON has no NaN (fitness and mismatch are finite:
    the protocol refuses others)."""
    out = {"timestamp": time_of(message.stamp_ns), "vehicle": vehicle, "fitness": float(message.fitness),
           "mismatch": float(message.mismatch), "converged": bool(message.converged),
           "good": bool(message.good), "generations": int(message.generations),
           "has_truth": errors is not None}
    if errors is not None:
        for name, value in zip(("error_position_m", "error_rotation_deg"), errors):
            if value is not None and np.isfinite(value):
                out[name] = float(value)
    return out


def load_target_model(name: str | None):
    """The target model file (a shipped name such as ``pioneer`` or a path); None for no model."""
    if not name:
        return None
    from scenarios.target import load_model, resolve_model_path

    return load_model(resolve_model_path(name))


def run_view(options: SessionOptions, stop: threading.Event, fleet: str, *, host: str = "127.0.0.1",
             port: int = 8765, model: str | None = "pioneer", duration: float | None = None,
             emit: Callable[[dict], None] | None = None) -> dict:
    """Serve the live view of ``fleet`` until ``stop`` (or ``duration`` s); emits ``ready`` with the actual port."""
    import foxglove

    from protocol.keys import check_name

    from agents.bridges.view_relay import SubprotocolRelay

    check_name(fleet, "fleet")
    emit = emit or (lambda record: None)
    target_model = load_target_model(model)
    context = foxglove.Context()
    view = FleetView(context, target_model)
    server = foxglove.start_server(name=f"evopose {fleet}", host="127.0.0.1", port=0, context=context)
    relay = SubprotocolRelay(host, port, server.port)
    started = time.monotonic()
    try:
        port = relay.start()
        with open_session(observer_options(options)) as session, FleetTap(session, fleet, view.handle) as tap:
            emit({"event": "ready", "fleet": fleet, "host": host, "port": port, "url": f"ws://{host}:{port}"})
            while not stop.wait(1.0 / VIEW_RATE_HZ):
                view.flush()
                if duration is not None and time.monotonic() - started >= duration:
                    break
    finally:
        relay.stop()
        server.stop()
    return {"event": "stopped", "logged": view.logged, "dropped": tap.dropped, "seconds": time.monotonic() - started}
