"""The roles of the target itself (paper §IV): the airship, which publishes its IMU attitude every frame and
receives its own pose back from the ground station (Experiment 1), and the simulated target, which publishes
its true pose (ground truth for observers, never used by the estimators)."""

from __future__ import annotations

import math

import numpy as np

from protocol import Attitude, PoseEstimate, Topic

from agents.transport.bus import Received
from agents.vehicle.config import TARGET_IMU_STREAM
from agents.vehicle.frames import NS
from agents.vehicle.records import pose_dict
from geometry import pose_error
from agents.vehicle.roles import Vehicle


class Airship(Vehicle):
    """Publishes its IMU attitude every frame; evaluates the poses the ground station sends back."""

    role = "airship"

    def subscribe(self) -> None:
        self.bus.subscribe(Topic.POSE)

    def frame(self, n: int) -> None:
        scene = n % self.scenario.frames
        truth = self.scenario.target_pose(scene)
        imu = self.scenario.target_imu
        if imu is not None:
            rpy = imu.read(truth[3:], self.scenario.seed, TARGET_IMU_STREAM, scene)
            sigma = float(math.hypot(imu.bias_sigma, imu.noise_sigma))
            self.bus.publish(Attitude(**self.bus.header(Topic.ATTITUDE, self.clock.stamp_ns(n)),
                                      body=self.config.vehicle, roll=float(rpy[0]), pitch=float(rpy[1]),
                                      yaw=float(rpy[2]), sigma=(sigma, sigma, sigma)))
        self._receive_own_pose()

    def _receive_own_pose(self) -> None:
        rx = self.bus.recv(Topic.POSE, timeout=0)
        while rx is not None:
            message = rx.message
            if isinstance(message, PoseEstimate) and message.target == self.config.vehicle:
                if self._plausible_own_pose(message):
                    self._own_pose(rx, message)
                else:
                    self.bus.counters.count_rejected(Topic.POSE.value, "outside-operating-area")
            rx = self.bus.recv(Topic.POSE, timeout=0)

    def _plausible_own_pose(self, message: PoseEstimate) -> bool:
        """Within the operating radius of where the airship is now (a 1e300 m pose is not taken as its own)."""
        here = self.scenario.target_pose(0)[:3]
        distance = np.linalg.norm(np.asarray(message.pose[:3], float) - here)
        return bool(np.isfinite(distance) and distance <= self.config.operating_radius_m)

    def _own_pose(self, rx: Received, message: PoseEstimate) -> None:
        k = self.clock.index_of(message.stamp_ns)
        if k is None:
            return
        error = pose_error(np.array(message.pose), self.scenario.target_pose(k % self.scenario.frames))
        self.record.estimates += 1
        self.record.last_pose, self.record.last_error = list(message.pose), error
        if message.converged:  # the search's own judgement, as the target counted it before the sender's verdict
            self.record.converged += 1
            self.record.errors.add(error)
            if self.record.first_good_s is None:
                self.record.first_good_s = (rx.received_ns - self._started_ns) / NS
        self.emit({"event": "own-pose", "vehicle": self.config.vehicle, "from": rx.vehicle, "frame": k,
                   "pose": pose_dict(np.array(message.pose)), "converged": message.converged,
                   "latency_s": (rx.received_ns - message.stamp_ns) / NS, "error": error})


class Target(Vehicle):
    """The simulated target: publishes its true pose every frame (ground truth for observers)."""

    role = "target"

    def frame(self, n: int) -> None:
        truth = self.scenario.target_pose(n % self.scenario.frames)
        self.bus.publish(PoseEstimate(**self.bus.header(Topic.POSE, self.clock.stamp_ns(n)),
                                      target=self.config.vehicle, pose=tuple(float(v) for v in truth), fitness=0.0,
                                      mismatch=0.0, converged=True, generations=0, seconds=0.0))


__all__ = ["Airship", "Target"]
