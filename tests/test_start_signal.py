"""`evopose agent --epoch-from-stdin` (agents/vehicle/start_signal.py): an agent warms up, says `warm`, and takes
frame 0's time from one line on its standard input, as `evopose scenario run` gives it to every agent of a run once
all are warm; a bad line, an input that ends or a stop before it are handled, never a hang."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time

import pytest

from agents.cli.main import main
from agents.errors import FleetError
from agents.experiments.runner import AgentProcess, ScenarioRunError, release_when_warm
from agents.vehicle.start_signal import parse_epoch, read_epoch
from tests.fleet_procs import ROOT, free_port

NOW = 1_800_000_000 * 10**9


def test_an_epoch_line_is_an_integer_of_ns_near_this_clock():
    assert parse_epoch(b"1800000001000000000\n", NOW) == NOW + 10**9
    assert parse_epoch(b"  1800000000000000000  ", NOW) == NOW
    with pytest.raises(FleetError, match="an integer, ns since the Unix epoch.*got 'soon'"):
        parse_epoch(b"soon", NOW)
    with pytest.raises(FleetError, match="within 3600 s of this machine's clock.*[+]7200 s"):
        parse_epoch(str(NOW + 7200 * 10**9).encode(), NOW)


def _pipe_with(data: bytes | None) -> int:
    """The read end of a pipe holding ``data``, its write end closed (``None``: left open, nothing written)."""
    read, write = os.pipe()
    if data is None:
        threading.Timer(30, os.close, (write,)).start()   # closed later, so the test never leaks a blocked reader
    else:
        os.write(write, data)
        os.close(write)
    return read


def test_the_epoch_is_read_from_the_input_and_an_ended_or_silent_one_is_one_line():
    now = time.time_ns()
    fd = _pipe_with(f"{now}\n".encode())
    assert read_epoch(threading.Event(), fd) == now
    fd = _pipe_with(f"{now}".encode())   # the last line without its newline
    assert read_epoch(threading.Event(), fd) == now
    with pytest.raises(FleetError, match="standard input ended before an epoch came"):
        read_epoch(threading.Event(), _pipe_with(b""))
    with pytest.raises(FleetError, match="at most 64 bytes"):
        read_epoch(threading.Event(), _pipe_with(b"1" * 200))
    with pytest.raises(FleetError, match="no epoch on standard input within 0.3 s"):
        read_epoch(threading.Event(), _pipe_with(None), timeout_s=0.3)
    stop = threading.Event()
    threading.Timer(0.2, stop.set).start()
    started = time.monotonic()
    assert read_epoch(stop, _pipe_with(None)) is None   # stopped while waiting: no epoch, no error
    assert time.monotonic() - started < 5


def test_both_epoch_options_are_one_line_and_exit_2(capsys):
    assert main(["agent", "--fleet", "t", "--vehicle", "H1", "--no-multicast", "--epoch-ns", "5",
                 "--epoch-from-stdin"]) == 2
    err = capsys.readouterr().err
    assert "--epoch-ns and --epoch-from-stdin both give frame 0's time: give one" in err and err.count("\n") == 1


def _agent(fleet: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "agents.cli", "agent", "--fleet", fleet, "--vehicle", "H1",
                             "--frames", "2", "--epoch-from-stdin", "--json", "--no-multicast", "--listen",
                             f"tcp/127.0.0.1:{free_port()}"], cwd=ROOT, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_a_warm_agent_takes_the_epoch_as_frame_0():
    agent = _agent("start-signal")
    try:
        assert json.loads(agent.stdout.readline()) == {"event": "warm", "vehicle": "H1"}
        epoch = time.time_ns() + int(1.5e9)
        out, err = agent.communicate(f"{epoch}\n", timeout=60)
    finally:
        agent.kill()
    assert agent.returncode == 0, err
    frames = [r for r in map(json.loads, out.splitlines()) if r.get("event") == "frame"]
    # the clock's ticks from the epoch given, at 10 fps (frame 0 itself unless this machine held the agent back for
    # 1.5 s: no timing is asserted here)
    assert len(frames) == 2 and [f["stamp_ns"] for f in frames] == [epoch + f["frame"] * 10**8 for f in frames]
    assert frames[1]["frame"] > frames[0]["frame"]


def test_the_runner_gives_every_agent_the_same_epoch_once_all_are_warm_and_stops_waiting_when_one_exits():
    child = ("import json, sys, time; time.sleep({}); print(json.dumps({{'event': 'warm'}})); sys.stdout.flush(); "
             "print(json.dumps({{'epoch': sys.stdin.readline().strip()}}))")
    procs = [AgentProcess(name, subprocess.Popen([sys.executable, "-c", child.format(delay)], stdin=subprocess.PIPE,
                                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
             for name, delay in (("slow", 1.0), ("fast", 0.0))]
    before = time.time_ns()
    assert release_when_warm(procs, threading.Event())
    for proc in procs:
        proc.finish(10)
    given = [int(proc.records[-1]["epoch"]) for proc in procs]
    # the same epoch, a second after the slower one was warm (a second after it started)
    assert given[0] == given[1] and before + 2 * 10**9 <= given[0] + 10**8 and given[0] < time.time_ns() + 10**9
    frozen = AgentProcess("frozen", subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"],
                                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True))
    try:   # a team-mate that never gets warm (hung in its start): the run fails naming it, it does not wait forever
        with pytest.raises(ScenarioRunError, match="agents frozen were not warm within 0.5 s"):
            release_when_warm([frozen], threading.Event(), timeout_s=0.5)
    finally:
        frozen.popen.kill()
    gone = AgentProcess("gone", subprocess.Popen([sys.executable, "-c", "pass"], stdin=subprocess.PIPE,
                                                 stdout=subprocess.PIPE, text=True))
    waiting = AgentProcess("waiting", subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"],
                                                       stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True))
    try:
        assert not release_when_warm([gone, waiting], threading.Event(), timeout_s=20)
    finally:
        waiting.popen.kill()


def test_a_bad_epoch_line_is_one_line_and_exit_2_and_a_stop_before_it_exits_cleanly():
    agent = _agent("start-signal-bad")
    try:
        assert json.loads(agent.stdout.readline())["event"] == "warm"
        _, err = agent.communicate("tomorrow\n", timeout=60)
    finally:
        agent.kill()
    assert agent.returncode == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "--epoch-from-stdin: expected one line holding the fleet clock's epoch" in err and "'tomorrow'" in err
    agent = _agent("start-signal-stop")
    try:
        assert json.loads(agent.stdout.readline())["event"] == "warm"
        agent.terminate()
        out, err = agent.communicate(timeout=30)
    finally:
        agent.kill()
    assert agent.returncode == 0 and out == "" and "Traceback" not in err, (out, err)
