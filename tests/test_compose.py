"""docker-compose files: the committed ones are what `evopose scenario compose` generates, and every service's
command is one the real CLI accepts (parsed and checked, never run: this machine has no Docker engine)."""

from __future__ import annotations

from pathlib import Path

import pytest
import typer
import typer.main
import yaml

from agents.cli.main import app, main
from agents.experiments.compose import compose_document, compose_yaml
from agents.vehicle.agent import resolve_role
from agents.vehicle.config import ENCODINGS, ROLES, SHARES
from agents.transport.session import SessionOptions, make_config
from scenarios.fleet import fleet_scenario_names, load_fleet_scenario
from scenarios.world import load_scenario

ROOT = Path(__file__).resolve().parents[1]
MAIN_SCENARIO = "exp2a-features"
REGENERATE = "out of date: run `make compose` to regenerate the compose files"

#: (committed file, scenario, build context relative to the file)
COMMITTED = [(ROOT / "docker-compose.yml", MAIN_SCENARIO, ".")] + [
    (ROOT / "compose" / f"{name}.yml", name, "..") for name in fleet_scenario_names()]
#: the secure compose file of the main scenario (TLS, mTLS, the router's ACL; docs/security.md)
SECURE = ROOT / "docker-compose.secure.yml"


def _id(case: tuple) -> str:
    return str(case[0].relative_to(ROOT))


@pytest.fixture(scope="module")
def cli():
    return typer.main.get_command(app)


def parse(cli, argv: list[str]):
    """Parse ``evopose ARGV`` down to the sub-command's context, as the CLI would, without invoking it.

    The click API (vendored by typer): ``make_context`` converts and validates every option (unknown ones,
    bad values and missing required ones raise) but does not call the command.
    """
    assert argv[0] == "evopose", argv
    root = cli.make_context("evopose", list(argv[1:2]))
    name, command, rest = cli.resolve_command(root, list(argv[1:]))
    return command.make_context(name, rest, parent=root)


def services_of(path: Path) -> dict:
    return yaml.safe_load(path.read_text(encoding="utf-8"))["services"]


@pytest.mark.parametrize("case", COMMITTED, ids=_id)
def test_committed_file_is_generated(case: tuple) -> None:
    path, name, context = case
    assert path.is_file(), f"{path.relative_to(ROOT)} is missing: {REGENERATE}"
    expected = compose_yaml(load_fleet_scenario(name), context=context)
    assert path.read_text(encoding="utf-8") == expected, f"{path.relative_to(ROOT)} is {REGENERATE}"
    assert yaml.safe_load(expected) == compose_document(load_fleet_scenario(name), context=context)


def test_no_stale_files() -> None:
    assert sorted(p.stem for p in (ROOT / "compose").glob("*.yml")) == fleet_scenario_names(), REGENERATE


def test_document_is_deterministic_and_relative() -> None:
    scenario = load_fleet_scenario(MAIN_SCENARIO)
    text = compose_yaml(scenario)
    assert text == compose_yaml(load_fleet_scenario(MAIN_SCENARIO))
    assert str(ROOT) not in text and "/work" not in text
    services = compose_document(scenario)["services"]
    assert list(services) == ["router", "h1", "h2", "pioneer"]
    assert services["router"]["ports"] == ["127.0.0.1:7447:7447"]
    for name, service in services.items():
        assert service["build"] == "." and service["image"] == "evopose-fleet"
        assert service["stop_signal"] == "SIGTERM" and service["init"] is True
        if name != "router":
            assert "router" in service["depends_on"]
            assert "--frames" not in service["command"]  # they run until stopped


def test_variant_selection() -> None:
    scenario = load_fleet_scenario("exp1-airship")
    first = compose_document(scenario)["services"]["ground-station"]["command"]
    imu = compose_document(scenario, "EvoPose+IMU")["services"]["ground-station"]["command"]
    assert "--no-imu" in first and "--no-imu" not in imu
    assert "--variant EvoPose+IMU" in compose_yaml(scenario, "EvoPose+IMU")


@pytest.mark.parametrize("case", COMMITTED, ids=_id)
def test_agent_commands_are_accepted(cli, case: tuple) -> None:
    path, name, _ = case
    services = services_of(path)
    scenario = load_fleet_scenario(name)
    vehicles = {s.lower(): s for s in (a.vehicle for a in scenario.spec.variants[0].agents)}
    agents = {k: v for k, v in services.items() if k != "router"}
    assert set(agents) == set(vehicles)
    for service_name, service in agents.items():
        ctx = parse(cli, service["command"])
        assert ctx.command.name == "agent"
        p = ctx.params
        assert p["vehicle"] == vehicles[service_name] and p["fleet"] == scenario.name
        assert p["share"] in SHARES and p["image_encoding"] in ENCODINGS and p["role"] in (None, *ROLES)
        assert p["frames"] is None and p["as_json"] and not p["multicast"] and p["mode"] == "client"
        assert p["connect"] == ["tcp/router:7447"]
        make_config(SessionOptions(mode=p["mode"], connect=tuple(p["connect"]), multicast=False))
        world_file = ROOT / p["scenario"]  # relative to the repository root (the image's working directory)
        assert not Path(p["scenario"]).is_absolute() and world_file.is_file()
        world = load_scenario(world_file)
        resolve_role(world, p["vehicle"], p["role"])
        team = p["wait_for"].split(",")
        assert sorted(team) == sorted(v for v in vehicles.values() if v != p["vehicle"])
        for mate in team:
            resolve_role(world, mate, None)


@pytest.mark.parametrize("case", COMMITTED, ids=_id)
def test_router_command_is_accepted(cli, case: tuple) -> None:
    router = services_of(case[0])["router"]
    ctx = parse(cli, router["command"])
    assert ctx.command.name == "router"
    assert ctx.params["listen"] == ["tcp/0.0.0.0:7447"] and not ctx.params["multicast"]
    make_config(SessionOptions(mode="router", listen=tuple(ctx.params["listen"]), multicast=False))


def test_parse_rejects_bad_commands(cli) -> None:
    """The check above is not vacuous: unknown options and bad values are refused."""
    command = compose_document(load_fleet_scenario(MAIN_SCENARIO))["services"]["h1"]["command"]
    with pytest.raises(typer.TyperException, match="--bogus"):
        parse(cli, [*command, "--bogus"])
    with pytest.raises(typer.BadParameter):
        parse(cli, [*command, "--seed", "-1"])
    with pytest.raises(typer.BadParameter):
        parse(cli, [*command, "--fps", "fast"])
    with pytest.raises(typer.TyperException, match="fleet"):
        parse(cli, [a for a in command if a not in ("--fleet", MAIN_SCENARIO)])
    with pytest.raises(typer.TyperException, match="agnet"):
        parse(cli, ["evopose", "agnet", "--fleet", "x"])


def test_cli_writes_and_prints(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "c.yml"
    assert main(["scenario", "compose", MAIN_SCENARIO, "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == compose_yaml(load_fleet_scenario(MAIN_SCENARIO))
    assert main(["scenario", "compose", "exp1-airship", "--variant", "EvoPose+IMU", "--context", ".."]) == 0
    assert capsys.readouterr().out == compose_yaml(load_fleet_scenario("exp1-airship"), "EvoPose+IMU",
                                                   context="..")


@pytest.mark.parametrize("argv", [["scenario", "compose", "nope"],
                                  ["scenario", "compose", MAIN_SCENARIO, "--variant", "nope"]])
def test_cli_errors(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "nope" in lines[0], captured.err


# -- the secure compose file -----------------------------------------------------------------------

def test_committed_secure_file_is_generated() -> None:
    assert SECURE.is_file(), f"{SECURE.name} is missing: {REGENERATE}"
    scenario = load_fleet_scenario(MAIN_SCENARIO)
    assert SECURE.read_text(encoding="utf-8") == compose_yaml(scenario, secure=True), f"{SECURE.name} is {REGENERATE}"
    assert yaml.safe_load(SECURE.read_text(encoding="utf-8")) == compose_document(scenario, secure=True)


def test_secure_services_get_only_their_own_credentials_and_their_configs_work(cli, tmp_path: Path) -> None:
    """Each service mounts the CA certificate and its own certificate, key and config (never ca.key nor another
    member's key); the commands parse; the configs that `evopose fleet credentials` writes for this file open
    as Zenoh configurations with the commands' options on top (the router's name is in its certificate)."""
    scenario = load_fleet_scenario(MAIN_SCENARIO)
    services = services_of(SECURE)
    header = SECURE.read_text(encoding="utf-8").splitlines()
    make = next(line for line in header if "evopose fleet credentials" in line).split(": ", 1)[1].split()
    directory = tmp_path / "credentials"
    assert main([*make[1:3], str(directory), *make[4:]]) == 0  # the command the header gives, into tmp_path
    for name, service in services.items():
        member = "router" if name == "router" else next(a.vehicle for a in scenario.spec.variants[0].agents
                                                        if a.vehicle.lower() == name)
        mounts = sorted(v.split(":")[0] for v in service["volumes"])
        assert mounts == sorted(f"./credentials/{f}" for f in ("ca.pem", f"{member}.pem", f"{member}.key",
                                                               f"{member}.json5"))
        assert all(v.endswith(":ro") and v.split(":")[1].startswith("/credentials/") for v in service["volumes"])
        ctx = parse(cli, service["command"])
        p = ctx.params
        assert str(p["config"]) == f"/credentials/{member}.json5"
        host_config = directory / f"{member}.json5"
        if name == "router":
            assert p["listen"] == ["tls/0.0.0.0:7447"]
            config = make_config(SessionOptions(mode="router", listen=tuple(p["listen"]), config_file=host_config))
            assert '"enable_mtls":true' in config.get_json("transport/link/tls").replace(" ", "")
            assert "true" in config.get_json("access_control/enabled")
        else:
            assert p["connect"] == ["tls/router:7447"] and p["mode"] is None  # client mode: from the file
            config = make_config(SessionOptions(connect=tuple(p["connect"]), config_file=host_config))
            assert config.get_json("mode") == '"client"'
    from cryptography import x509

    router_cert = x509.load_pem_x509_certificate((directory / "router.pem").read_bytes())
    names = router_cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "router" in names.get_values_for_type(x509.DNSName)
