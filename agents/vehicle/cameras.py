"""A camera vehicle's camera, chosen from its configuration: the renderer, a real image source (a file, a sequence, a
device: :mod:`agents.vehicle.sources`), a rendered dataset (:mod:`agents.vehicle.dataset_source`) or ROS 2 topics
(:mod:`agents.vehicle.ros_camera`, imported only when an input is a ``ros2:`` topic: it brings in the bridges).
"""

from __future__ import annotations

from pathlib import Path

from geometry import matrix_from_pose
from scenarios.world import Scenario

from agents.errors import FleetError
from agents.problem.camera_info import read_camera_info, read_camera_pose
from vision.extract import feature_extractor, resolve_features
from agents.transport.bus import FleetBus
from agents.vehicle.config import AgentConfig
from agents.vehicle.dataset_source import dataset_location, open_dataset_camera
from agents.vehicle.frames import SimulatedCamera, fleet_clock
from agents.vehicle.sources import NEW_IMAGE_WAIT_SHARE, SourceCamera, is_ros, open_reader


def _mark_scorer(config: AgentConfig):
    """``--mark-scorer``'s scorer, read now: None (the shipped ones), ``"bars"`` or a file's; a bad file is one
    :class:`FleetError`."""
    if config.mark_scorer is None or str(config.mark_scorer) == "shipped":
        return None
    if str(config.mark_scorer) == "bars":
        return "bars"
    from vision.mark_scorer import load

    try:
        return load(Path(config.mark_scorer))
    except OSError as error:
        raise FleetError(f"--mark-scorer {config.mark_scorer}: cannot read it ({error.strerror or error})") from None
    except ValueError as error:
        raise FleetError(f"--mark-scorer {config.mark_scorer}: {error}") from None


def open_camera(config: AgentConfig, scenario: Scenario, bus: FleetBus | None = None) -> SimulatedCamera | SourceCamera:
    """The vehicle's camera: the renderer, or ``config.source`` with its camera files and topics (files read now, so
    that a bad one is an error before the vehicle joins its fleet).

    ROS 2 topics are followed on ``bus``'s Zenoh session. Without a bus (the warm-up, before the vehicle joins), a
    camera with a ROS input is checked (topic names, files) and is then the renderer: its first frame compiles the
    same kernels, and no ROS message can arrive before the session is open.
    """
    scorer = _mark_scorer(config)
    try:
        camera_images = config.source is not None or scenario.render.camera_model is not None
        extract = feature_extractor(resolve_features(config.features, camera_images), scenario.model,
                                    scenario.bounds() if scenario.spec.search else None, scorer,
                                    period_s=1.0 / (config.fps or scenario.spec.fps))
    except ValueError as error:  # a scorer fitted on another palette
        raise FleetError(f"--mark-scorer {config.mark_scorer}: {error}") from None
    if config.source is None:
        return SimulatedCamera(scenario, config.vehicle, extract)
    ros_inputs = any(is_ros(spec) for spec in (config.source, config.camera_info, config.camera_pose))
    if ros_inputs:  # imported here: it brings in the bridges (rosbags)
        from agents.vehicle.ros_camera import check_ros_topics, open_ros_camera

        check_ros_topics(config)
    k_file = None if config.camera_info is None or is_ros(config.camera_info) else read_camera_info(config.camera_info)
    pose_file = None if config.camera_pose is None or is_ros(config.camera_pose) else \
        matrix_from_pose(read_camera_pose(config.camera_pose))
    located = None if ros_inputs else dataset_location(config.source)
    if located is not None:  # a rendered dataset (docs/datasets.md): its images, per-frame cameras and truth
        # a common clock (--epoch-ns): the dataset's frame k is the fleet's frame k; else from the first tick
        return open_dataset_camera(str(config.source), located, scenario, config.vehicle, extract,
                                   fleet_clock(config.fps, scenario, config.epoch_ns),
                                   first_tick=0 if config.epoch_ns else None, intrinsics=k_file,
                                   world_from_camera=pose_file, intrinsics_from=None if config.camera_info is None
                                   else f"--camera-info {config.camera_info}")
    if ros_inputs and bus is None:
        if not is_ros(config.source):
            open_reader(str(config.source)).close()
        return SimulatedCamera(scenario, config.vehicle, extract)
    if ros_inputs:
        return open_ros_camera(config, scenario, bus, extract, k_file, pose_file)
    return SourceCamera(open_reader(str(config.source), NEW_IMAGE_WAIT_SHARE / (config.fps or scenario.spec.fps)),
                        scenario, config.vehicle, extract,
                        intrinsics=None if k_file is None else (lambda: k_file),
                        world_from_camera=None if pose_file is None else (lambda _stamp: pose_file),
                        intrinsics_from=None if config.camera_info is None else f"--camera-info {config.camera_info}")


__all__ = ["open_camera"]
