"""What ``evopose agent`` runs: the vehicle's configuration and the names of roles and share modes.

Light on purpose (no numpy, no Zenoh): the CLI imports it to build its options.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from agents.errors import FleetError

ROLES = ("uav", "ground-station", "airship", "target")
SHARES = ("none", "raw", "features", "hint")
ENCODINGS = ("raw", "jpeg", "png")
#: Eq. (4)'s view weights (evopose.weights): fixed, the paper's step rule, or from each view's evidence.
VIEW_WEIGHTS = ("equal", "step", "adaptive")
CAMERA_ROLES = ("uav", "ground-station")
#: Feature points a camera vehicle extracts (``--features``): scenarios.fleet.FEATURE_KINDS, here without pydantic
#: for the CLI's help (tests/test_scenarios.py checks they are the same).
FEATURES = ("auto", "marks", "contrast", "corners")
#: Largest ROS_DOMAIN_ID (ROS 2's documented range, as ``evopose ros2 --domain``).
MAX_ROS_DOMAIN = 232
#: IMU random stream of the scenario's target (as in scenarios.render's ground truth).
TARGET_IMU_STREAM = 1000


@dataclass(frozen=True)
class AgentConfig:
    """What ``evopose agent`` runs; see the CLI's help for each field."""

    fleet: str
    vehicle: str
    #: the world file or shipped name; None: the dataset's world with a dataset ``source``, else exp2
    scenario: str | Path | None
    role: str | None = None
    share: str = "none"
    frames: int | None = None
    fps: float | None = None
    epoch_ns: int = 0
    #: wait, once warm, for the epoch on standard input (agents.vehicle.start_signal) instead of ``epoch_ns``
    epoch_from_stdin: bool = False
    seed: int = 0
    world_seed: int | None = None
    max_age_s: float = 1.0
    sync_wait_s: float | None = None
    hint_rate_hz: float = 200.0
    image_encoding: str = "raw"
    use_attitude: bool = True
    attitude_sigmas: float = 1.0
    wait_for: tuple[str, ...] = ()
    wait_timeout_s: float = 10.0
    time_budget_s: float | None = None
    operating_radius_m: float = 1000.0
    max_clock_offset_s: float = 0.5
    #: a real image source (video file, image sequence, V4L2 device) instead of the renderer; see vehicle.sources
    source: str | None = None
    camera_info: str | Path | None = None
    camera_pose: str | Path | None = None
    #: ROS_DOMAIN_ID of the ``ros2:`` inputs (--source, --camera-info, --camera-pose)
    ros_domain: int = 0
    #: a ROS image or camera pose whose sample arrived longer ago than this (s) is stale: the frame is skipped
    source_max_age_s: float = 1.0
    #: with ``camera_pose`` a ros2: TFMessage topic (``/tf``): the camera's optical frame, composed from ``map``
    camera_frame: str | None = None
    features: str = "auto"
    #: with ``features`` contrast (or auto on camera images): which spots are marks: ``shipped`` (None: the shipped
    #: scorers), ``bars`` (the hand-set bars), or a scorer's JSON (``evopose train-scorer``) replacing the shipped one
    #: of its kind
    mark_scorer: str | Path | None = None
    view_weights: str = "step"

    def check(self) -> None:
        """Raise :class:`FleetError` naming the first bad field."""
        from protocol.keys import check_name

        check_name(self.fleet, "fleet"), check_name(self.vehicle, "vehicle")
        for name in self.wait_for:
            check_name(name, "--wait-for vehicle")
        if self.epoch_from_stdin and self.epoch_ns:
            raise FleetError("--epoch-ns and --epoch-from-stdin both give frame 0's time: give one")
        if self.role is not None and self.role not in ROLES:
            raise FleetError(f"--role must be one of {', '.join(ROLES)}, got {self.role!r}")
        if self.share not in SHARES:
            raise FleetError(f"--share must be one of {', '.join(SHARES)}, got {self.share!r}")
        if self.view_weights not in VIEW_WEIGHTS:
            raise FleetError(f"--view-weights must be one of {', '.join(VIEW_WEIGHTS)}, got {self.view_weights!r}")
        if self.features not in FEATURES:
            raise FleetError(f"--features must be one of {', '.join(FEATURES)}, got {self.features!r}")
        if self.mark_scorer is not None and self.features not in ("contrast", "auto"):
            raise FleetError(f"--mark-scorer is for --features contrast, got --features {self.features}")
        if self.source is None and (self.camera_info is not None or self.camera_pose is not None):
            raise FleetError("--camera-info and --camera-pose describe a real camera: they need --source")
        if self.source is not None and not str(self.source).strip():
            raise FleetError("--source must not be empty")
        if self.camera_frame is not None and not str(self.camera_pose or "").startswith("ros2:"):
            raise FleetError("--camera-frame names a frame of /tf: it needs --camera-pose ros2:/tf")
        if not 0 <= self.ros_domain <= MAX_ROS_DOMAIN:
            raise FleetError(f"--ros-domain must be a ROS_DOMAIN_ID from 0 to {MAX_ROS_DOMAIN}, got {self.ros_domain}")
        if self.image_encoding not in ENCODINGS:
            raise FleetError(f"--image-encoding must be one of {', '.join(ENCODINGS)}, got {self.image_encoding!r}")
        for name, option in (("fps", "--fps"), ("hint_rate_hz", "--hint-rate"), ("max_age_s", "--max-age"),
                             ("attitude_sigmas", "--imu-sigmas"), ("operating_radius_m", "--operating-radius"),
                             ("max_clock_offset_s", "--max-clock-offset"), ("source_max_age_s", "--source-max-age")):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise FleetError(f"{option} must be a number > 0, got {value}")
