"""Issue 12, identity and access control, and safe defaults: real processes over real Zenoh on loopback, multicast
scouting off (docs/security.md).

- ``evopose fleet credentials`` writes a CA, one certificate per vehicle (its name as common name), keys 0600,
  and Zenoh configurations that Zenoh accepts;
- a router with that configuration refuses clients without a fleet certificate, and drops what a vehicle with
  valid credentials publishes under another vehicle's key (no subscriber sees it), while its own messages pass;
- a legitimate secure team (``scenario run --secure``) converges as usual;
- defaults: loopback listeners, multicast off, agents that only connect still meet (in a loopback-only network
  namespace when this machine can make one), a team that never met and a duplicate vehicle name are one-line
  errors with exit code 2.

Readiness is always a handshake (a ``ready`` line, a message that arrives); nothing waits a fixed time.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import stat
import subprocess
import sys
import threading
import uuid
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.hazmat.primitives.serialization import load_pem_private_key
from cryptography.x509.oid import NameOID

from agents.cli.main import main
from agents.runs import pose_rows
from agents.transport.credentials import create_credentials, fleet_keys
from agents.transport.session import (MAX_MESSAGE_BYTES, PEER_LISTEN, ROUTER_LISTEN, SHARED_MEMORY_KEY,
                                     SessionOptions, listen_endpoints, make_config)
from tests.fleet_procs import ROOT, Proc, free_port

VEHICLES = ("H1", "H2", "pioneer")
CLI = [sys.executable, "-m", "agents.cli"]
PROCS = [sys.executable, "-m", "tests.security_procs"]


class Piped(Proc):
    """A :class:`Proc` with a stdin pipe: the security_procs helpers stay until it is closed."""

    def __init__(self, args: list[str]) -> None:  # noqa: D107 - as Proc, plus stdin
        self.args = args
        self.popen = subprocess.Popen(args, cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, text=True)
        self.lines = queue.Queue()
        self.records = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def release(self, timeout: float = 20.0) -> int:
        self.popen.stdin.close()
        return self.wait(timeout)


@pytest.fixture
def procs():
    started: list[Proc] = []

    def start(args: list[str], piped: bool = False) -> Proc:
        proc = (Piped if piped else Proc)(args)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.kill()


def one_error_line(proc: Proc, timeout: float = 60.0) -> str:
    """Wait for ``proc`` to exit with code 2 and return its single stderr line."""
    code = proc.wait(timeout)
    err = proc.popen.stderr.read()
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), (code, err)
    return lines[0]


# -- the credentials ---------------------------------------------------------------------------------------

def test_credentials_are_a_ca_a_certificate_per_vehicle_and_private_keys(tmp_path: Path) -> None:
    made = create_credentials(tmp_path / "c", "alpha", VEHICLES, observers=["meter"], router_hosts=["router"])
    d = made.directory
    ca = x509.load_pem_x509_certificate((d / "ca.pem").read_bytes())
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    for member in (*VEHICLES, "meter", "router"):
        cert = x509.load_pem_x509_certificate((d / f"{member}.pem").read_bytes())
        key = load_pem_private_key((d / f"{member}.key").read_bytes(), None)
        assert isinstance(key, ec.EllipticCurvePrivateKey) and key.curve.name == "secp256r1"
        assert b"BEGIN PRIVATE KEY" in (d / f"{member}.key").read_bytes()  # PKCS#8
        assert stat.S_IMODE((d / f"{member}.key").stat().st_mode) == 0o600
        assert cert.issuer == ca.subject and cert.public_key().public_numbers() == key.public_key().public_numbers()
        cert.verify_directly_issued_by(ca)
        if member != "router":
            assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == member
    assert stat.S_IMODE((d / "ca.key").stat().st_mode) == 0o600
    san = x509.load_pem_x509_certificate((d / "router.pem").read_bytes()).extensions.get_extension_for_class(
        x509.SubjectAlternativeName).value
    assert set(san.get_values_for_type(x509.DNSName)) == {"localhost", "router"}
    assert [str(a) for a in san.get_values_for_type(x509.IPAddress)] == ["127.0.0.1"]
    # Zenoh reads every configuration (unknown keys are errors there); the file names resolve beside the file
    router = make_config(SessionOptions(config_file=made.router_config))
    tls = json.loads(router.get_json("transport/link/tls"))
    assert tls["enable_mtls"] and tls["listen_private_key"] == str(d / "router.key")
    assert json.loads(router.get_json("listen/endpoints")) == ["tls/127.0.0.1:7447"]
    acl = json.loads(router.get_json("access_control"))
    assert acl["enabled"] and acl["default_permission"] == "deny"
    by_id = {r["id"]: r for r in acl["rules"]}
    assert by_id["publish-H1"]["key_exprs"] == ["evopose/alpha/H1/**"] and by_id["publish-H1"]["flows"] == ["ingress"]
    assert by_id["presence-H1"]["key_exprs"] == ["evopose/alpha/@alive/H1"]
    assert "publish-meter" not in by_id  # an observer publishes nothing
    assert {"id": "vehicle-H1", "cert_common_names": ["H1"]} in [
        {k: v for k, v in s.items() if v is not None} for s in acl["subjects"]]
    client = make_config(SessionOptions(config_file=made.config("H1")))
    tls = json.loads(client.get_json("transport/link/tls"))
    assert json.loads(client.get_json("mode")) == "client" and tls["verify_name_on_connect"] and tls["enable_mtls"]
    assert tls["connect_certificate"] == str(d / "H1.pem") and tls["root_ca_certificate"] == str(d / "ca.pem")
    assert fleet_keys("alpha") == ("evopose/alpha/**", "evopose/alpha/@alive/*")


def test_credentials_command_refuses_to_overwrite_and_bad_names(tmp_path: Path, capsys) -> None:
    args = ["fleet", "credentials", str(tmp_path / "c"), "--fleet", "alpha", "--vehicles", "H1,H2"]
    assert main(args) == 0
    assert main(args) == 2 and "--force" in capsys.readouterr().err
    assert main([*args, "--force"]) == 0
    for bad in (["--vehicles", "H1,H1"], ["--vehicles", "a/b"], ["--vehicles", "router"],
                ["--listen", "tcp/127.0.0.1:7447"]):
        capsys.readouterr()
        assert main([*args[:-2], *bad, "--force"]) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and err[0].startswith("error: ")


# -- a router with the fleet's ACL -----------------------------------------------------------------------

@pytest.fixture
def secure_fleet(tmp_path: Path, procs):
    """A router with mTLS and the ACL of fleet ``alpha`` on a free port; returns (credentials, endpoint)."""
    endpoint = f"tls/127.0.0.1:{free_port()}"
    made = create_credentials(tmp_path / "alpha", "alpha", VEHICLES, observers=["meter"], listen=endpoint)
    router = procs([*CLI, "router", "--config", str(made.router_config), "--json"])
    ready = router.next_record(60, lambda r: r.get("event") == "ready")
    assert ready["listen"] == [endpoint]
    return made, endpoint


def test_a_client_without_a_fleet_certificate_cannot_connect(secure_fleet, tmp_path: Path, procs) -> None:
    made, endpoint = secure_fleet
    watcher = procs([*PROCS, "watch", str(made.config("meter")), "alpha"], piped=True)
    watcher.next_record(60, lambda r: r.get("event") == "ready")
    port = endpoint.rsplit(":", 1)[1]
    # TLS that trusts the fleet's CA but presents no certificate
    no_cert = tmp_path / "no-cert.json5"
    no_cert.write_text(json.dumps({"mode": "client", "connect": {"endpoints": [endpoint]},
                                   "transport": {"link": {"tls": {"root_ca_certificate": str(made.ca_certificate)}}}}))
    # a certificate of the same name from another CA
    other = create_credentials(tmp_path / "other", "alpha", VEHICLES, listen=endpoint)
    intruders = {
        "no certificate": ["--config", str(no_cert)],
        "another CA": ["--config", str(other.config("H1"))],
        "plain TCP": ["--mode", "client", "--connect", f"tcp/127.0.0.1:{port}"],
    }
    for what, net in intruders.items():
        proc = procs([*CLI, "listen", "--fleet", "alpha", "--vehicle", "H1", "--duration", "5", *net])
        line = one_error_line(proc)
        assert "cannot open the Zenoh session" in line, (what, line)
        assert not [r for r in proc.all_records() if r.get("event") == "ready"], what
    # a member does connect, and the watcher sees it: the fleet is up, the intruders were never in it
    member = procs([*PROCS, "forge", str(made.config("H2")), "alpha", "H2", "H2", "1"], piped=True)
    member.next_record(60, lambda r: r.get("event") == "done")
    watcher.next_record(30, lambda r: r.get("event") == "sample" and r["key"] == "evopose/alpha/H2/hint")
    assert member.release() == 0 and watcher.release() == 0
    seen = watcher.all_records()
    assert not [r for r in seen if r.get("event") == "token" and r["key"].endswith("/H1")]
    assert {r["key"] for r in seen if r.get("event") == "sample"} == {"evopose/alpha/H2/hint"}


def test_a_vehicle_cannot_publish_under_another_vehicles_key(secure_fleet, procs) -> None:
    made, _ = secure_fleet
    count = 50
    watchers = [procs([*PROCS, "watch", str(made.config(member)), "alpha"], piped=True)
                for member in ("pioneer", "meter")]
    for watcher in watchers:
        watcher.next_record(60, lambda r: r.get("event") == "ready")
    # H2's credentials: its own hints and token alternate with forged ones under H1's key and token
    forger = procs([*PROCS, "forge", str(made.config("H2")), "alpha", "H1", "H2", str(count)], piped=True)
    forger.next_record(60, lambda r: r.get("event") == "done")
    for watcher in watchers:
        own = 0
        while own < count:  # the last own hint came after every forged one, over the same links
            watcher.next_record(60, lambda r: r.get("event") == "sample")
            own = sum(1 for r in watcher.records if r.get("event") == "sample" and "/H2/" in r["key"])
    assert forger.release() == 0
    for watcher in watchers:
        assert watcher.release() == 0
        records = watcher.all_records()
        keys = [r["key"] for r in records if r.get("event") == "sample"]
        assert keys == ["evopose/alpha/H2/hint"] * count  # nothing under H1's key
        tokens = {r["key"] for r in records if r.get("event") == "token"}
        assert "evopose/alpha/@alive/H1" not in tokens and "evopose/alpha/@alive/H2" in tokens


def test_the_real_publish_tool_with_another_members_file_is_refused(secure_fleet, procs) -> None:
    """`evopose publish --vehicle H1` with the meter's file (an observer: it may only watch) is dropped by the
    router; the same command with H1's own file goes through."""
    made, _ = secure_fleet
    watcher = procs([*PROCS, "watch", str(made.config("pioneer")), "alpha"], piped=True)
    watcher.next_record(60, lambda r: r.get("event") == "ready")
    publish = [*CLI, "publish", "--fleet", "alpha", "--vehicle", "H1", "--topic", "hint", "--count", "5",
               "--rate", "100", "--wait", "30"]
    observer = procs([*publish, "--config", str(made.config("meter"))])
    assert observer.wait(60) == 0 and observer.next_record(5)["sent"] == 5  # sent; the router dropped them
    # the observer's session is closed: whatever the router let through of it was forwarded before this starts
    legit = procs([*publish, "--config", str(made.config("H1"))])
    assert legit.wait(60) == 0 and legit.next_record(5)["sent"] == 5
    hints = 0
    while hints < 5:
        watcher.next_record(60, lambda r: r.get("event") == "sample")
        hints = sum(1 for r in watcher.records if r.get("event") == "sample" and r["key"] == "evopose/alpha/H1/hint")
    assert watcher.release() == 0
    assert sum(1 for r in watcher.all_records() if r.get("key") == "evopose/alpha/H1/hint") == 5


def test_a_secure_team_converges_as_usual() -> None:
    port = free_port()
    out = subprocess.run([*CLI, "scenario", "run", "exp2a-features", "--secure", "--frames", "10", "--json",
                          "--listen", f"tcp/127.0.0.1:{port}"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads(out.stdout)
    (run,) = result["runs"]
    assert run["secure"] and not run["interrupted"]
    for vehicle in ("H1", "H2"):
        summary = run["agents"][vehicle]
        # converged (how many frames that takes depends on the machine's load; the end state does not)
        assert summary["estimates"] == 10 and summary["good"] >= 1 and pose_rows(summary)[-1].good, summary
        assert summary["error_position"] < 0.05 and summary["last_error"]["position"] < 0.05, summary
        # the team-mate's feature sets came through the router and were used as views (eq. 4)
        assert summary["traffic"]["received"].get("features", 0) >= 1 and summary["multi_view_frames"] >= 1


# -- safe defaults -----------------------------------------------------------------------------------------

def test_defaults_listen_on_loopback_with_multicast_off(tmp_path: Path) -> None:
    router = SessionOptions(mode="router")
    assert listen_endpoints(router) == (ROUTER_LISTEN,) == ("tcp/127.0.0.1:7447",)
    assert listen_endpoints(SessionOptions(connect=("tcp/127.0.0.1:7447",))) == (PEER_LISTEN,)
    assert listen_endpoints(SessionOptions(mode="client", connect=("tcp/127.0.0.1:7447",))) == ()
    assert listen_endpoints(SessionOptions(mode="router", listen=("tcp/0.0.0.0:7447",))) == ("tcp/0.0.0.0:7447",)
    assert json.loads(make_config(router).get_json("scouting/multicast/enabled")) is False
    assert json.loads(make_config(SessionOptions(multicast=True)).get_json("scouting/multicast/enabled")) is True
    chosen = tmp_path / "z.json5"  # a file that chooses its endpoints (or its message bound) keeps them
    chosen.write_text('{mode: "router", listen: {endpoints: ["tcp/127.0.0.2:7447"]}, '
                      'transport: {link: {rx: {max_message_size: 65536}}}}')
    assert listen_endpoints(SessionOptions(config_file=chosen)) == ("tcp/127.0.0.2:7447",)
    key = "transport/link/rx/max_message_size"
    assert json.loads(make_config(SessionOptions(config_file=chosen)).get_json(key)) == 65536
    assert json.loads(make_config(router).get_json(key)) == MAX_MESSAGE_BYTES == 16 * 2**20


def test_shared_memory_is_off_unless_the_file_sets_it(tmp_path: Path) -> None:
    """Zenoh's shared-memory pools held ~45 MB of each agent sharing raw images (agents/transport/session.py)."""
    assert json.loads(make_config(SessionOptions()).get_json(f"{SHARED_MEMORY_KEY}/enabled")) is False
    chosen = tmp_path / "z.json5"
    chosen.write_text('{transport: {shared_memory: {enabled: true, mode: "init"}}}')
    assert json.loads(make_config(SessionOptions(config_file=chosen)).get_json(f"{SHARED_MEMORY_KEY}/enabled")) is True


def _listening(pid: int) -> set[tuple[str, int]]:
    """(address, port) of the TCP sockets ``pid`` listens on (from /proc: its fds' inodes in LISTEN state)."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    found = set()
    for table, width in (("tcp", 8), ("tcp6", 32)):
        for line in Path(f"/proc/{pid}/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] == "0A" and fields[9] in inodes:  # LISTEN
                address, port = fields[1].split(":")
                found.add((address if width == 32 else ".".join(str(int(address[i:i + 2], 16))
                                                               for i in (6, 4, 2, 0)), int(port, 16)))
    return found


@pytest.mark.skipif(not Path("/proc/self/net/tcp").exists(), reason="needs Linux /proc")
def test_a_peer_given_only_connect_listens_on_loopback_only(procs) -> None:
    port = free_port()
    first = procs([*CLI, "listen", "--fleet", "lo", "--vehicle", "a", "--listen", f"tcp/127.0.0.1:{port}"])
    first.next_record(60, lambda r: r.get("event") == "ready")
    second = procs([*CLI, "listen", "--fleet", "lo", "--vehicle", "b", "--connect", f"tcp/127.0.0.1:{port}"])
    second.next_record(60, lambda r: r.get("event") == "ready")
    _joined(second, "a")  # it met the listening peer
    sockets = _listening(second.popen.pid)
    assert sockets and all(address == "127.0.0.1" for address, _ in sockets), sockets


def test_a_team_that_never_met_is_an_error(procs) -> None:
    port = free_port()  # nobody listens there: the agent connects to no one
    lonely = procs([*CLI, "agent", "--fleet", "never", "--vehicle", "pioneer", "--connect",
                    f"tcp/127.0.0.1:{port}", "--wait-for", "H1", "--wait-timeout", "1", "--frames", "1"])
    line = one_error_line(lonely)
    assert "H1" in line and "did not appear" in line


def test_a_second_agent_with_the_same_name_refuses_to_start(procs) -> None:
    port = free_port()
    first = procs([*CLI, "agent", "--fleet", "twins", "--vehicle", "pioneer", "--listen", f"tcp/127.0.0.1:{port}",
                   "--json"])
    first.next_record(120, lambda r: r.get("event") == "ready")
    second = procs([*CLI, "agent", "--fleet", "twins", "--vehicle", "pioneer", "--connect", f"tcp/127.0.0.1:{port}",
                    "--frames", "1", "--json"])
    line = one_error_line(second)
    assert "already present" in line and "pioneer" in line
    other = procs([*CLI, "agent", "--fleet", "twins", "--vehicle", "H1", "--connect", f"tcp/127.0.0.1:{port}",
                   "--share", "none", "--frames", "1", "--wait-for", "pioneer", "--json"])
    assert other.wait(120) == 0  # another name joins the same fleet
    code, _ = first.stop(timeout=30)
    assert code == 0


# -- without auto-discovery, in a loopback-only network namespace -----------------------------------------

@pytest.fixture
def netns():
    """A fresh network namespace with only ``lo`` (up): no other interface, no multicast route to anyone."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("making a network namespace needs root and iproute2")
    name = f"evopose-{uuid.uuid4().hex[:8]}"
    if subprocess.run(["ip", "netns", "add", name], capture_output=True).returncode != 0:
        pytest.skip("this machine cannot make a network namespace")
    try:
        subprocess.run(["ip", "netns", "exec", name, "ip", "link", "set", "lo", "up"], check=True)
        yield ["ip", "netns", "exec", name]
    finally:
        subprocess.run(["ip", "netns", "del", name], capture_output=True)


def _joined(proc: Proc, mate: str, timeout: float = 60.0) -> None:
    """Wait until ``proc`` (an ``evopose listen``) has reported ``mate`` joining."""
    if not any(r.get("event") == "join" and r.get("vehicle") == mate for r in proc.all_records()):
        proc.next_record(timeout, lambda r: r.get("event") == "join" and r["vehicle"] == mate)


def _members_meet(start, prefix: list[str], fleet: str, net_of: dict[str, list[str]]) -> None:
    """Start one ``evopose listen`` per member (multicast off by default) and wait until each saw every other."""
    members = {}
    for vehicle, net in net_of.items():
        members[vehicle] = start([*prefix, *CLI, "listen", "--fleet", fleet, "--vehicle", vehicle, *net])
        members[vehicle].next_record(60, lambda r: r.get("event") == "ready")
    for vehicle, proc in members.items():
        for mate in members:
            if mate != vehicle:
                _joined(proc, mate)
    for proc in members.values():
        proc.kill()


def test_agents_that_only_connect_meet_through_the_listening_peer_or_the_router(netns, procs) -> None:
    # peer to peer: one listens, the others only connect (and so listen on loopback): all three meet
    port = 7447
    _members_meet(procs, netns, "p2p", {"a": ["--listen", f"tcp/127.0.0.1:{port}"],
                                      "b": ["--connect", f"tcp/127.0.0.1:{port}"],
                                      "c": ["--connect", f"tcp/127.0.0.1:{port}"]})
    # through a router: clients only
    router = procs([*netns, *CLI, "router", "--listen", f"tcp/127.0.0.1:{port + 1}", "--json"])
    router.next_record(60, lambda r: r.get("event") == "ready")
    client = ["--mode", "client", "--connect", f"tcp/127.0.0.1:{port + 1}"]
    _members_meet(procs, netns, "routed", {"a": client, "b": client})
    # the agents themselves: a team that only connects, through the router, runs and exits 0
    agents = [procs([*netns, *CLI, "agent", "--fleet", "team", "--vehicle", v, "--frames", "2", "--wait-for", mate,
                     "--json", *client]) for v, mate in (("H1", "pioneer"), ("pioneer", "H1"))]
    for agent in agents:
        assert agent.wait(180) == 0, agent.popen.stderr.read()
        assert [r for r in agent.all_records() if r.get("event") == "summary"]
    # and two agents that only connect to an endpoint nobody listens on never meet: exit 2, one line each
    lonely = [procs([*netns, *CLI, "agent", "--fleet", "alone", "--vehicle", v, "--wait-for", mate,
                     "--wait-timeout", "2", "--frames", "1", "--connect", f"tcp/127.0.0.1:{port + 2}"])
              for v, mate in (("H1", "pioneer"), ("pioneer", "H1"))]
    for agent in lonely:
        assert "did not appear" in one_error_line(agent, 120)
