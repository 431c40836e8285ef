"""`make test` runs the suite in two passes: tests that run vehicles on a frame clock or measure rates and delays
between real processes ("realtime") one at a time, as before, and everything else on two workers
(pytest-xdist) first. A real-time test shares the machine with nothing but its own processes, so a late frame is
the code's, not a neighbouring test's."""

from __future__ import annotations

import pytest

#: Test modules whose tests start agents on a frame clock, time a budget, or measure rates between processes.
REALTIME_MODULES = frozenset({
    "test_agents", "test_bus", "test_dataset_agents", "test_dataset_scenario", "test_faults", "test_fleet",
    "test_flood", "test_meter_ros2", "test_netns", "test_paper_scale", "test_plausibility", "test_record", "test_ros2",
    "test_ros_hints", "test_ros_sources", "test_scenarios", "test_security", "test_sources", "test_time_budget",
    "test_vehicle_realtime", "test_view",
})


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "realtime: runs processes in real time; `make test` runs these one at a time")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.module is not None and item.module.__name__.rsplit(".", 1)[-1] in REALTIME_MODULES:
            item.add_marker(pytest.mark.realtime)
