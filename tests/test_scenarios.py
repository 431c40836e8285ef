"""Fleet scenarios: the shipped files validate, `evopose scenario run` starts every agent as a process, is
watchable from outside at its endpoint, prints results, and leaves nothing running (also on SIGINT)."""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path

import pytest

from agents.cli.main import main
from agents.experiments.results import agreement
from scenarios.errors import ScenarioError
from scenarios.fleet import fleet_scenario_names, load_fleet_scenario
from tests.fleet_procs import Proc, free_port, good_from_first


def running_with(text: str) -> list[int]:
    """PIDs of live processes whose command line contains ``text``."""
    pids = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            if text in cmdline.read_bytes().replace(b"\0", b" ").decode(errors="replace"):
                pids.append(int(cmdline.parent.name))
        except OSError:
            continue
    return pids


def wait_for(pids, timeout: float = 30.0) -> list[int]:
    """Poll ``pids()`` until it returns a non-empty list (or ``timeout`` passes); that list."""
    deadline = time.monotonic() + timeout
    found = pids()
    while not found and time.monotonic() < deadline:
        time.sleep(0.1)
        found = pids()
    return found


def start_endless_run(scenario: str) -> tuple[Proc, str]:
    """`evopose scenario run SCENARIO` with frames enough never to end by itself, on a free endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    return Proc([sys.executable, "-m", "agents.cli", "scenario", "run", scenario, "--frames", "10000", "--listen",
                 endpoint, "--json"]), endpoint


def watch(endpoint: str) -> Proc:
    """`evopose meter` on the fleet at ``endpoint``; its per-second records name every key an agent has published on."""
    return Proc([sys.executable, "-m", "agents.cli", "meter", "--connect", endpoint, "--no-multicast", "--json"])


def published(meter: Proc, runner: Proc, *key_suffixes: str, timeout: float = 60.0) -> None:
    """Wait until the meter has seen messages on keys ending with each of ``key_suffixes`` (e.g. ``/H1/pose``);
    fail at once, with the runner's error, if the run ends before that."""
    missing = set(key_suffixes)
    deadline = time.monotonic() + timeout
    while missing:
        assert runner.popen.poll() is None, f"the run ended before {sorted(missing)}: {runner.stderr_now()}"
        assert time.monotonic() < deadline, f"the meter saw nothing on {sorted(missing)} in {timeout} s: " \
                                            f"{meter.stderr_now()}"
        try:
            record = meter.next_record(1.0, lambda r: r.get("type") == "rate")
        except AssertionError:  # nothing metered in this second: look at the run again
            continue
        missing = {suffix for suffix in missing if not record["key"].endswith(suffix)}


def test_shipped_scenarios_validate_and_name_the_paper_experiments():
    assert set(fleet_scenario_names()) == {"exp1-airship", "exp2-solo", "exp2a-features", "exp2b-hints", "exp2-raw",
                                           "exp2-four-features", "exp2-four-hints", "exp2-eight-features",
                                           "exp2-eight-hints", "exp2-team-size"}
    for n, count in (("four", 4), ("eight", 8)):
        team = load_fleet_scenario(f"exp2-{n}-features")
        assert team.world.name == f"exp2-{n}" and len(team.world.vehicles) == count and team.spec.router
        assert {a.share for a in team.spec.variants[0].agents if a.vehicle.startswith("H")} == {"features"}
    sizes = load_fleet_scenario("exp2-team-size")  # issue 13: one world and rate for every team size
    teams = {v.name: [a.vehicle for a in v.agents if a.vehicle.startswith("H")] for v in sizes.spec.variants}
    assert teams == {"1-alone": ["H1"], **{f"{n}-{share}": [f"H{i}" for i in range(1, n + 1)]
                                           for share in ("features", "hints") for n in (2, 4, 8)}}
    exp1 = load_fleet_scenario("exp1-airship")
    assert [v.name for v in exp1.spec.variants] == ["EvoPose", "EvoPose+IMU"]
    shares = {n: {a.share for a in load_fleet_scenario(n).spec.variants[0].agents if a.vehicle.startswith("H")}
              for n in ("exp2-solo", "exp2a-features", "exp2b-hints", "exp2-raw")}
    assert shares == {"exp2-solo": {"none"}, "exp2a-features": {"features"}, "exp2b-hints": {"hint"},
                      "exp2-raw": {"raw"}}


@pytest.mark.parametrize("body, message", [
    ("world: exp2\nvariants: [{name: a, agents: [{vehicle: H7}]}]", "variants[0].agents[0].vehicle: 'H7' is not in"),
    ("world: exp2\nvariants: [{name: a, agents: [{vehicle: H1, share: smoke}]}]", "variants[0].agents[0].share"),
    ("world: exp2\nvariants: [{name: a, agents: [{vehicle: H1, colour: red}]}]", "colour"),
    ("world: nowhere\nvariants: [{name: a, agents: [{vehicle: H1}]}]", "world:"),
    ("world: exp2\nvariants: [{name: a, agents: [{vehicle: pioneer, role: uav}]}]", "agents[0].role: pioneer is the"),
])
def test_a_bad_scenario_file_gets_one_line_naming_the_field(tmp_path, body, message, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text("name: bad\n" + body + "\n")
    with pytest.raises(ScenarioError) as err:
        load_fleet_scenario(path)
    assert message in str(err.value) and "\n" not in str(err.value)
    assert main(["scenario", "run", str(path)]) == 2
    assert capsys.readouterr().err.startswith("error: ")


def test_scenario_run_is_watchable_and_leaves_nothing_running():
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    runner = Proc([sys.executable, "-m", "agents.cli", "scenario", "run", "exp2a-features", "--frames", "25",
                   "--listen", endpoint, "--json"])
    meter = Proc([sys.executable, "-m", "agents.cli", "meter", "--connect", endpoint, "--no-multicast", "--json",
                  "--duration", "30"])
    try:
        rate = meter.next_record(40, lambda r: r.get("type") == "rate" and r["key"].endswith("/H2/features"))
        assert 300 < rate["size_mean"] < 1000
        result = runner.next_record(90, lambda r: "rows" in r)
        assert runner.wait(10) == 0
    finally:
        meter.kill()
        runner.kill()
    by_vehicle = {r["vehicle"]: r for r in result["rows"]}
    assert set(by_vehicle) == {"H1", "H2"}
    for vehicle in ("H1", "H2"):  # a few frames of search, then the target is held
        first, held = good_from_first(result["runs"][0]["agents"][vehicle])
        assert first <= 10 and held, vehicle  # a few generations per frame, then held
    assert agreement(result["runs"], "H1", "H2")["position_max"] <= 0.01
    # the rows, by hand from the run's agent summaries: one run, so each mean is that run's value and each σ 0
    [run] = result["runs"]
    assert set(run["agents"]) == {"H1", "H2", "pioneer"}  # the target estimates nothing: no row
    for vehicle, row in by_vehicle.items():
        s = run["agents"][vehicle]
        assert (row["scenario"], row["variant"], row["share"], row["runs"]) == (
            "exp2a-features", run["variant"], "features", 1)
        for name in ("roll", "pitch", "yaw", "x", "y", "z", "position"):
            assert (row[name], row[f"{name}_sd"]) == (s[f"error_{name}"], 0.0), name
        assert row["good_fraction"] == s["good"] / s["frames"] and s["frames"] == 25
        assert row["multi_view_fraction"] == s["multi_view_frames"] / s["estimates"]
        seconds = s["frames"] / s["fps"]
        assert row["traffic"]["features"] == pytest.approx(
            {"rate_hz": s["traffic"]["sent"]["features"] / seconds,
             "bytes_per_message": s["traffic"]["bytes_sent"]["features"] / s["traffic"]["sent"]["features"],
             "bytes_per_s": s["traffic"]["bytes_sent"]["features"] / seconds})
        # the costs (issue 13's team-size table): the whole process's CPU over the run's span, every topic
        assert 0 < s["render_cpu_s"] < s["cpu_s"] <= s["run_s"] * (os.cpu_count() or 1), s
        assert row["cpu_per_frame_s"] == s["cpu_s"] / 25 and row["render_per_frame_s"] == s["render_cpu_s"] / 25
        assert row["bytes_sent_per_s"] == sum(s["traffic"]["bytes_sent"].values()) / s["run_s"]
        assert row["bytes_received_per_s"] == sum(s["traffic"]["bytes_received"].values()) / s["run_s"] > 0
    assert running_with(endpoint) == []


def test_sigint_stops_every_agent_of_a_running_scenario():
    runner, endpoint = start_endless_run("exp2b-hints")
    meter = watch(endpoint)
    try:
        published(meter, runner, "/H1/pose", "/H1/hint")  # past frame 0: H1 has published an estimate and a hint
        meter.kill()
        code, seconds = runner.stop(signal.SIGINT, timeout=20)
        result = runner.next_record(5, lambda r: "rows" in r)
    finally:
        meter.kill()
        runner.kill()
    assert code == 0 and seconds < 15 and result["interrupted"]
    assert running_with(endpoint) == []
    summaries = result["runs"][0]["agents"]
    assert summaries["H1"]["frames"] > 0 and summaries["H1"]["traffic"]["sent"]["hint"] > 0


def test_scenario_list_and_show(capsys):
    assert main(["scenario", "list", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert {item["name"] for item in listed} == set(fleet_scenario_names())
    assert main(["scenario", "show", "exp2b-hints", "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["variants"][0]["agents"][0] == {"vehicle": "H1", "role": None, "share": "hint", "imu": True,
                                                  "hint_rate": 200.0, "image_encoding": "raw", "features": None}


@pytest.mark.untimed("waits for the run's end after one agent is killed")
def test_a_crashed_agent_ends_the_run_with_one_line_and_stops_the_others():
    runner, endpoint = start_endless_run("exp2a-features")
    meter = watch(endpoint)
    try:
        victim = wait_for(lambda: [pid for pid in running_with(endpoint) if pid in running_with("--vehicle H2 ")])
        assert victim
        published(meter, runner, "/H2/features")  # running: H2 shares its feature sets
        meter.kill()
        os.kill(victim[0], signal.SIGKILL)
        code = runner.wait(30)
    finally:
        meter.kill()
        runner.kill()
    err = runner.popen.stderr.read()
    assert code == 2 and err.startswith("error: run 0 of exp2a-features/H1+H2: H2 exited -9"), err
    assert err.count("\n") == 1
    assert running_with(endpoint) == []


def test_features_override_sets_every_camera_vehicles_front_end_and_a_bad_kind_is_one_line(capsys):
    scenario = load_fleet_scenario("exp2a-features").with_features("contrast")
    args = {a.vehicle: a.cli_args() for a in scenario.spec.variants[0].agents}
    assert args["H1"][-2:] == ["--features", "contrast"] and args["H2"][-2:] == ["--features", "contrast"]
    assert "--features" not in args["pioneer"]  # the target has no camera
    with pytest.raises(ScenarioError, match="features"):
        load_fleet_scenario("exp2a-features").with_features("hues")
    assert main(["scenario", "run", "exp2a-features", "--features", "hues"]) == 2
    err = capsys.readouterr().err
    assert "--features" in err and "auto, marks, contrast, corners" in err and err.count("\n") == 1


def test_the_feature_kinds_are_one_list():
    from vision.extract import FEATURE_KINDS as extractors
    from agents.vehicle.config import FEATURES
    from scenarios.fleet import FEATURE_KINDS

    assert FEATURES == FEATURE_KINDS == extractors == ("auto", "marks", "contrast", "corners")
