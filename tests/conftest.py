"""`make test` runs the suite in two passes: tests that run vehicles on a frame clock and assert when something
happens between real processes (no late frame, views paired in time, a rate, a delay, a reconnection time:
"realtime") one at a time, and everything else on two workers (pytest-xdist) first. A real-time test shares the
machine with nothing but its own processes, so a late frame is the code's, not a neighbouring test's. The other
modules that start processes (a secure team, recordings, the ROS 2 mirror and hints, plausibility) assert what
arrives and a team's end state over a fixed count of processed frames, never when: a neighbouring test slows them
and changes nothing they check. `make suite-cost` (benchmarks/suite_cost.py) says where each pass's time goes."""

from __future__ import annotations

import pytest

#: Test modules with a test that asserts no late frame, views paired in time (a pair publishing the same pose), a
#: rate, a delay or a time between real processes. test_dataset_scenario's pair on a recording failed on the two
#: workers (2 of 10 frames paired: a team-mate's view came after the frame's wait for it). A test of one of these
#: modules that only waits for what arrives is marked ``untimed`` and runs on the workers.
REALTIME_MODULES = frozenset({
    "test_agents", "test_bus", "test_dataset_agents", "test_dataset_scenario", "test_faults", "test_fleet",
    "test_flood", "test_netns", "test_paper_scale", "test_ros_sources", "test_scenarios", "test_sources",
    "test_time_budget", "test_vehicle_realtime", "test_view",
})


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "realtime: asserts timing between processes; `make test` runs these one at "
                                       "a time")
    config.addinivalue_line("markers", "untimed(why): a test of a real-time module that waits for what arrives and "
                                       "asserts no time; `make test` runs it on the two workers")


def pytest_ignore_collect(collection_path, config: pytest.Config) -> bool | None:
    """``-m realtime`` (the second pass) imports only the real-time modules (collecting every module costs ~5 s)."""
    if config.option.markexpr == "realtime" and collection_path.suffix == ".py":
        return collection_path.stem.startswith("test_") and collection_path.stem not in REALTIME_MODULES
    return None


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        module = item.module.__name__.rsplit(".", 1)[-1] if item.module is not None else None
        if module in REALTIME_MODULES and item.get_closest_marker("untimed") is None:
            item.add_marker(pytest.mark.realtime)
