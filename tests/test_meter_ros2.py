"""`evopose meter` prints exactly what `ros2 topic hz` and `ros2 topic bw` print (ros2cli ros2topic/verb/hz.py and
bw.py: the format strings and how the numbers are computed), pure, without Zenoh."""

from __future__ import annotations

import math

import pytest

from agents.tools.meter import KeyWindow, ros2_bw_line, ros2_hz_line


def window_of(arrivals: list[float], sizes: list[int], size: int = 100) -> KeyWindow:
    window = KeyWindow(size)
    for t, n in zip(arrivals, sizes):
        window.add(t, n)
    return window


def test_hz_is_computed_over_window_periods_as_ros2cli_does():
    arrivals = [0.0, 0.1, 0.25, 0.3, 0.5]
    hz = window_of(arrivals, [10] * 5).report(0.6)["ros2_hz"]
    periods = [0.1, 0.15, 0.05, 0.2]
    mean = sum(periods) / 4
    assert hz["window"] == 4 and hz["rate"] == pytest.approx(1 / mean)
    assert (hz["min"], hz["max"]) == pytest.approx((0.05, 0.2))
    assert hz["std_dev"] == pytest.approx(math.sqrt(sum((p - mean) ** 2 for p in periods) / 4))  # population
    long = window_of([i * 0.01 for i in range(500)], [1] * 500, size=100).report(5.0)
    assert long["ros2_hz"]["window"] == 100 and long["window"] == 100 and long["ros2_bw"]["messages"] == 100


def test_bandwidth_is_the_windows_bytes_over_the_time_since_its_first_arrival():
    window = window_of([0.0, 0.5, 1.0], [100, 200, 300])
    assert window.report(1.0)["ros2_bw"] == {"bytes_per_s": 600.0, "messages": 3, "mean": 200.0, "min": 100,
                                             "max": 300}
    assert window.report(3.0)["ros2_bw"]["bytes_per_s"] == pytest.approx(200.0)  # falls when the topic stops


def test_the_lines_are_ros2clis_byte_for_byte():
    hz = {"rate": 199.96912, "min": 0.0049, "max": 0.0132, "std_dev": 0.001449, "window": 100}
    assert ros2_hz_line(hz) == "average rate: 199.969\n\tmin: 0.005s max: 0.013s std dev: 0.00145s window: 100"
    assert ros2_bw_line({"bytes_per_s": 640.4, "messages": 8, "mean": 24.0, "min": 24, "max": 24}) == \
        "640 B/s from 8 messages\n\tMessage size mean: 24 B min: 24 B max: 24 B"
    assert ros2_bw_line({"bytes_per_s": 4823.0, "messages": 100, "mean": 24.0, "min": 24, "max": 24}) == \
        "4.82 KB/s from 100 messages\n\tMessage size mean: 0.02 KB min: 0.02 KB max: 0.02 KB"
    assert ros2_bw_line({"bytes_per_s": 9.2e6, "messages": 10, "mean": 921654.0, "min": 921654, "max": 921654}) == \
        "9.20 MB/s from 10 messages\n\tMessage size mean: 0.92 MB min: 0.92 MB max: 0.92 MB"
