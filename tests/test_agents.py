"""Vehicle agents as real processes over real Zenoh on loopback (peer to peer, multicast scouting off):
feature sharing (agreement, rate, sizes), hints (24 bytes, > 100 Hz, better than alone), raw images,
eq. (3) from the airship's IMU, a killed team-mate, garbage and oversized payloads, bad arguments."""

from __future__ import annotations

import signal
import sys
import threading

import numpy as np
import pytest

from agents.cli.main import main
from agents.tools.runners import PublishSpec, run_publisher
from agents.transport.session import SessionOptions
from protocol import Topic
from tests.fleet_procs import Proc, free_port, good_from_first, release_when_warm

FEATURE_SIZE = range(100, 1000)
RAW_FRAME = 640 * 480 * 3


class Team:
    """Agents of one fleet sharing a frame clock; the first listens on a free port, the others connect to it. The
    agents started before :meth:`release` take the clock's epoch from it once all are warm (as ``evopose scenario
    run`` starts a run); those started after, the same epoch (``--epoch-ns``)."""

    def __init__(self, name: str, scenario: str = "exp2", fps: float = 10.0) -> None:
        self.fleet, self.scenario, self.fps = name, scenario, fps
        self.port = free_port()
        self.epoch: int | None = None
        self.procs: dict[str, Proc] = {}

    def start(self, vehicle: str, *args: str, frames: int | None = None, wait_for: str = "",
              listen: bool = False) -> Proc:
        net = ["--listen" if listen else "--connect", f"tcp/127.0.0.1:{self.port}", "--no-multicast"]
        run = [] if frames is None else ["--frames", str(frames)]
        clock = ["--epoch-from-stdin"] if self.epoch is None else ["--epoch-ns", str(self.epoch)]
        proc = Proc([sys.executable, "-m", "agents.cli", "agent", "--fleet", self.fleet, "--vehicle", vehicle,
                     "--scenario", self.scenario, "--fps", str(self.fps), *clock, "--json",
                     "--wait-for", wait_for, *run, *args, *net])
        self.procs[vehicle] = proc
        return proc

    def release(self) -> None:
        """Frame 0 a second after every agent started so far is warm."""
        self.epoch = release_when_warm(list(self.procs.values()))

    def summaries(self, timeout: float = 60) -> dict[str, dict]:
        return {v: p.next_record(timeout, lambda r: r.get("event") == "summary") for v, p in self.procs.items()}

    def frames(self, vehicle: str) -> dict[int, dict]:
        return {r["frame"]: r for r in self.procs[vehicle].all_records() if r.get("event") == "frame"}

    def close(self) -> None:
        for proc in self.procs.values():
            proc.kill()


@pytest.fixture
def teams():
    made: list[Team] = []

    def make(*args, **kwargs) -> Team:
        made.append(Team(*args, **kwargs))
        return made[-1]

    yield make
    for team in made:
        team.close()


def pair(team: Team, share: str, frames: int, *extra: str) -> dict[str, dict]:
    team.start("H1", "--share", share, *extra, frames=frames, wait_for="H2", listen=True)
    team.start("H2", "--share", share, *extra, frames=frames, wait_for="H1")
    team.release()
    return team.summaries()


#: Frames a search from scratch may take before the first good pose: a few generations per frame on shared views,
#: then a confirming search when the pose came from a team-mate (the time itself: BENCHMARKS.md, bench_fleet).
SEARCH_FRAMES = 10


def pose_of(record: dict) -> np.ndarray:
    return np.array([record["pose"][n] for n in ("x", "y", "z", "roll", "pitch", "yaw")])


def test_feature_sharing_pairs_both_views_and_both_publish_the_same_pose(teams):
    team = teams("features")
    s = pair(team, "features", 20)
    for vehicle in ("H1", "H2"):
        summary = s[vehicle]
        # the camera rate is a timing: tested in process (tests/test_vehicle_realtime.py), measured in BENCHMARKS.md
        # (bench_fleet: sustained fps, skipped frames)
        first, held = good_from_first(summary)
        assert summary["frames"] == summary["estimates"] == 20 and first <= SEARCH_FRAMES and held, summary["poses"]
        assert summary["multi_view_frames"] >= 15
        assert summary["error_position"] < 0.02
        traffic = summary["traffic"]
        assert traffic["sent"]["features"] == 20 and traffic["received"]["features"] >= 15
        assert traffic["bytes_sent"]["features"] // traffic["sent"]["features"] in FEATURE_SIZE
    h1, h2 = team.frames("H1"), team.frames("H2")
    # the same inputs: both views, of the same instant, on both (a late team-mate's previous view is not)
    both = [n for n in h1 if n in h2 and h1[n]["views"] == h2[n]["views"] == ["H1", "H2"]
            and h1[n]["views_of_this_instant"] and h2[n]["views_of_this_instant"]]
    assert len(both) >= 15
    for n in both:
        d = pose_of(h1[n]) - pose_of(h2[n])
        assert np.linalg.norm(d[:3]) <= 0.01 and np.degrees(np.abs(d[3:])).max() <= 0.1, (n, d)


def test_the_first_frame_waits_for_the_camera_team_mates_not_for_the_target_they_waited_for(teams):
    """A scenario's agents wait for every other vehicle, the target too; the first frame then waits up to --max-age
    for the team's views, and the target has none to share: it waited them out (1 s of frames at the default)."""
    team = teams("first-frame")
    team.start("H1", "--share", "features", "--max-age", "5", frames=10, wait_for="H2,pioneer", listen=True)
    team.start("H2", "--share", "features", "--max-age", "5", frames=10, wait_for="H1,pioneer")
    team.start("pioneer", "--share", "none", frames=10, wait_for="H1,H2")
    team.release()
    s = team.summaries()
    for vehicle in ("H1", "H2"):  # 5 s waited out would skip ~50 frames of the 10 fps clock
        assert s[vehicle]["late_frames"] < 20 and s[vehicle]["multi_view_frames"] >= 8, s[vehicle]


def test_hints_are_24_bytes_flow_above_100_hz_and_leave_the_pose_as_good_as_alone(teams):
    alone = pair(teams("alone"), "none", 30)
    hinted = pair(teams("hints"), "hint", 30)
    for vehicle in ("H1", "H2"):
        seconds = hinted[vehicle]["run_s"]  # the first frame's instant to the last frame's end
        assert seconds >= (30 - 1) / 10.0  # 29 frame periods at least (more when ticks were missed)
        traffic = hinted[vehicle]["traffic"]
        assert traffic["bytes_sent"]["hint"] == 24 * traffic["sent"]["hint"]
        assert traffic["sent"]["hint"] / seconds > 100, traffic
        assert traffic["received"]["hint"] > 100 * seconds * 0.9
        assert "hint" not in alone[vehicle]["traffic"]["sent"]
    # Table II (b): a hint is taken only when it fits the own image about as well, and the pose is then refined
    # on the own image, so at the telephoto scale hints do not change the pose: bench_fleet (BENCHMARKS.md) measures
    # the same error alone and hinted (H1 2.62 / 2.62 mm, H2 41.93 / 41.93 mm at 10 fps); H2's 42 mm is its view's
    # precision, not a wrong basin a hint could rescue. The bound is the run-to-run spread of 30 frames, not a
    # claim of improvement; the paper's gain for H2 (a wrong-basin rescue) is tested at paper scale
    # (test_paper_scale.py).
    for vehicle in ("H1", "H2"):
        assert hinted[vehicle]["error_position"] < 1.25 * alone[vehicle]["error_position"], (vehicle, hinted, alone)


def test_raw_images_cost_thousands_of_times_a_feature_set(teams):
    team = teams("raw")
    s = pair(team, "raw", 10)
    for vehicle in ("H1", "H2"):
        traffic = s[vehicle]["traffic"]
        size = traffic["bytes_sent"]["image"] / traffic["sent"]["image"]
        assert RAW_FRAME < size < RAW_FRAME + 1000
        assert traffic["received"]["image"] >= 8 and s[vehicle]["multi_view_frames"] >= 7
        assert s[vehicle]["error_position"] < 0.02


def test_ground_station_holds_the_airship_attitude_and_sends_it_its_pose(teams):
    team = teams("exp1", scenario="exp1-airship")
    team.start("ground-station", frames=15, wait_for="airship", listen=True)
    team.start("airship", frames=40, wait_for="ground-station")  # it publishes for as long as the station looks
    team.release()
    station = team.procs["ground-station"].first_record(60, lambda r: r.get("event") == "summary")
    team.procs["airship"].stop(signal.SIGTERM, timeout=15)
    s = {v: p.first_record(30, lambda r: r.get("event") == "summary") for v, p in team.procs.items()}
    frames = team.frames("ground-station")
    with_imu = [f for f in frames.values() if f["knowledge"] == ["roll", "pitch", "yaw"]]
    assert len(frames) == 15 and len(with_imu) >= 14  # the first frame may come before the first reading
    station, airship = s["ground-station"], s["airship"]
    assert station["traffic"]["received"]["attitude"] >= 12 and airship["traffic"]["sent"]["attitude"] >= 15
    assert station["error_roll"] < 3.0 and station["error_position"] < 0.15
    own = [r for r in team.procs["airship"].all_records() if r.get("event") == "own-pose"]
    assert airship["converged"] >= 10 and len(own) >= 10 and all(r["from"] == "ground-station" for r in own)
    assert airship["error_position"] < 0.15


def test_a_killed_teammate_is_dropped_from_the_views_and_used_again_when_back(teams):
    team = teams("kill")
    h1 = team.start("H1", "--share", "features", "--max-age", "0.5", wait_for="H2", listen=True)
    h2 = team.start("H2", "--share", "features", wait_for="H1")
    team.release()
    h1.next_record(40, lambda r: r.get("event") == "frame" and r["views"] == ["H1", "H2"])
    h2.kill()  # SIGKILL: no goodbye
    h1.next_record(10, lambda r: r.get("event") == "leave" and r["vehicle"] == "H2")
    # the frame in progress when H2 left may still use its last view; the next ones are H1's alone
    alone = h1.next_record(2, lambda r: r.get("event") == "frame" and r["views"] == ["H1"])
    h2 = team.start("H2", "--share", "features", wait_for="H1")
    back = h1.next_record(40, lambda r: r.get("event") == "frame" and r["views"] == ["H1", "H2"])
    assert back["frame"] > alone["frame"]
    code, seconds = h1.stop(signal.SIGTERM)
    assert code == 0 and seconds < 5
    summary = [r for r in h1.all_records() if r.get("event") == "summary"][0]
    # while H2 was gone and when it came back, H1 kept its pose (its camera rate: BENCHMARKS.md, bench_fleet)
    first, held = good_from_first(summary)
    assert held and first <= SEARCH_FRAMES, summary["poses"]


def test_garbage_and_oversized_payloads_on_every_key_do_not_stop_an_agent(teams):
    team = teams("garbage")
    h1 = team.start("H1", "--share", "features", listen=True)
    team.release()
    h1.next_record(40, lambda r: r.get("event") == "frame")
    # fifteen senders at once, each its own Zenoh session (evopose publish's, in threads of this process: the
    # attack is what reaches the agent, not fifteen interpreters starting)
    options, sent = SessionOptions(connect=(f"tcp/127.0.0.1:{team.port}",)), []
    attackers = [threading.Thread(target=lambda i=i, topic=topic, payload=payload: sent.append(run_publisher(
                     options, threading.Event(), team.fleet, f"evil{i}",
                     PublishSpec(Topic(topic), rate_hz=50, count=10, payload=payload))["sent"]))
                 for i, topic in enumerate(("features", "hint", "image", "attitude", "pose"))
                 for payload in ("garbage", "oversized", "truncated")]
    for thread in attackers:
        thread.start()
    for thread in attackers:
        thread.join(30)
    assert sent == [10] * 15
    h1.next_record(30, lambda r: r.get("event") == "frame" and r["good"])  # it still estimates, and well
    assert h1.popen.poll() is None
    code, _ = h1.stop(signal.SIGTERM)
    summary = [r for r in h1.all_records() if r.get("event") == "summary"][0]
    assert code == 0
    rejected = summary["traffic"]["rejected"]
    assert sum(rejected.values()) >= 20 and {"oversized", "malformed"} <= set(rejected), rejected
    first, held = good_from_first(summary)
    assert summary["frames"] == summary["estimates"] and held, summary["poses"]


@pytest.mark.parametrize("args, message", [
    (["--vehicle", "H9"], "--vehicle 'H9' is not in scenario 'exp2'"),
    (["--vehicle", "H1", "--share", "telepathy"], "--share must be one of none, raw, features, hint"),
    (["--vehicle", "pioneer", "--role", "uav"], "is the scenario's target"),
    (["--vehicle", "H1", "--scenario", "missing.yaml"], "missing.yaml: cannot read"),
    (["--vehicle", "H1", "--fps", "-3"], "must be a number > 0"),
    (["--vehicle", "H1", "--imu-sigmas", "0"], "--imu-sigmas must be a number > 0, got 0.0"),
    (["--vehicle", "H1", "--view-weights", "loudest"], "--view-weights must be one of equal, step, adaptive"),
])
def test_bad_agent_arguments_get_one_line_and_exit_code_2(args, message, capsys):
    assert main(["agent", "--fleet", "t", *args, "--no-multicast"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1, err
