"""Fleet scenarios: which vehicles of a world run as agents, and what they share (``scenarios/fleet/*.yaml``).

A fleet scenario names a world (a scenario file of :mod:`scenarios.world`: target, vehicles, renderer) and
one or more *variants*, each a team of agents started together as separate processes::

    name: exp2a-features
    description: H1 and H2 exchange feature sets (paper Table II, row H1 + H2)
    world: exp2                 # scenarios/exp2.yaml, or a path relative to this file
    frames: 30                  # frames per run (default: the world's)
    fps: 10                     # optional: the camera rate (default: the world's)
    router: false               # true: a Zenoh router is started and the agents join it as clients
    variants:
      - name: H1+H2
        agents:
          - {vehicle: H1, share: features}
          - {vehicle: H2, share: features}
          - {vehicle: pioneer}              # the target (its role comes from the world)

Agent fields: ``vehicle``; ``role`` (default: the world's); ``share`` (none, raw, features, hint);
``imu`` (a ground station holds the attitude within the airship's IMU reading, eq. 3; default true);
``hint_rate`` (Hz); ``image_encoding`` (raw, jpeg, png); ``features``, the camera vehicle's feature front-end
(marks, contrast, corners; default: the agent's, ``marks``). Unknown keys are errors naming the field.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal, get_args

from pydantic import Field, model_validator

from .documents import Strict, read_mapping, validate
from .errors import ScenarioError
from .world import SCENARIOS_DIR, Scenario, load_scenario

#: Directory of the shipped fleet scenarios.
FLEET_DIR = SCENARIOS_DIR / "fleet"

Share = Literal["none", "raw", "features", "hint"]
#: The kinds of feature points (``--features``; vision.extract): ``auto`` (the default: ``contrast`` on
#: camera images, ``marks`` on the project's flat-coloured drawings), colour ``marks`` by preset hue bands, marks by
#: ``contrast`` (camera images: photoreal renders, real cameras, any look), chessboard ``corners``.
Features = Literal["auto", "marks", "contrast", "corners"]
FEATURE_KINDS: tuple[str, ...] = get_args(Features)
Name = Annotated[str, Field(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}$")]


class AgentSpec(Strict):
    vehicle: Name
    role: Literal["uav", "ground-station", "airship", "target"] | None = None
    share: Share = "none"
    imu: bool = True
    hint_rate: Annotated[float, Field(gt=0, le=10_000)] = 200.0
    image_encoding: Literal["raw", "jpeg", "png"] = "raw"
    features: Features | None = None

    def cli_args(self) -> list[str]:
        """The ``evopose agent`` options of this agent (without fleet, network and run settings)."""
        args = ["--vehicle", self.vehicle, "--share", self.share]
        if self.role is not None:
            args += ["--role", self.role]
        if not self.imu:
            args.append("--no-imu")
        if self.share == "hint":
            args += ["--hint-rate", f"{self.hint_rate:g}"]
        if self.share == "raw" and self.image_encoding != "raw":
            args += ["--image-encoding", self.image_encoding]
        if self.features is not None:
            args += ["--features", self.features]
        return args


class VariantSpec(Strict):
    name: Annotated[str, Field(min_length=1, max_length=40)]
    agents: Annotated[list[AgentSpec], Field(min_length=1)]

    @model_validator(mode="after")
    def _unique(self) -> "VariantSpec":
        names = [a.vehicle for a in self.agents]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"a vehicle runs once per variant; repeated: {repeated}")
        return self


class FleetScenarioSpec(Strict):
    name: Name
    description: str = ""
    world: str
    frames: Annotated[int, Field(ge=1, le=1_000_000)] | None = None
    fps: Annotated[float, Field(gt=0, le=1000)] | None = None
    router: bool = False
    paper: str = ""
    variants: Annotated[list[VariantSpec], Field(min_length=1)]

    @model_validator(mode="after")
    def _unique(self) -> "FleetScenarioSpec":
        names = [v.name for v in self.variants]
        if len(set(names)) != len(names):
            raise ValueError(f"variant names must be unique, got {names}")
        return self


class FleetScenario:
    """A validated fleet scenario and its world."""

    def __init__(self, spec: FleetScenarioSpec, world: Scenario, path: Path, world_path: Path) -> None:
        self.spec, self.world, self.path, self.world_path = spec, world, path, world_path

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def frames(self) -> int:
        return self.spec.frames or self.world.frames

    @property
    def fps(self) -> float:
        return self.spec.fps or self.world.spec.fps

    def with_features(self, kind: str) -> "FleetScenario":
        """The same scenario with every camera vehicle's feature front-end set to ``kind`` (``scenario run
        --features``): for example the contrast front-end on a camera's or a photoreal dataset's images."""
        document = self.spec.model_dump()
        for variant in document["variants"]:
            for agent in variant["agents"]:
                if agent["vehicle"] != self.world.spec.target.name:
                    agent["features"] = kind
        spec = validate(FleetScenarioSpec, document, f"--features {kind}", ScenarioError)
        return FleetScenario(spec, self.world, self.path, self.world_path)

    def variant(self, name: str) -> VariantSpec:
        for v in self.spec.variants:
            if v.name == name:
                return v
        raise ScenarioError(f"scenario {self.name!r} has no variant {name!r} "
                            f"(variants: {', '.join(v.name for v in self.spec.variants)})")


def fleet_scenario_names() -> list[str]:
    """Names of the shipped fleet scenarios, sorted."""
    return sorted(p.stem for p in FLEET_DIR.glob("*.yaml"))


def resolve_fleet_path(name_or_path: str | Path) -> Path:
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml", ".json") or p.exists():
        return p
    shipped = FLEET_DIR / f"{p.name}.yaml"
    if not shipped.exists():
        raise ScenarioError(f"no fleet scenario {str(name_or_path)!r}; shipped: {', '.join(fleet_scenario_names())}")
    return shipped


def world_names() -> list[str]:
    """Names of the shipped worlds (``scenarios/*.yaml``), sorted."""
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.yaml"))


def resolve_world_path(world: str | Path, relative_to: Path | None = None) -> Path:
    """A world given by shipped name (``exp2-paper-scale``) or by file (relative to ``relative_to``)."""
    world_path = Path(world)
    if not world_path.suffix:
        world_path = SCENARIOS_DIR / f"{world}.yaml"
        if not world_path.exists():
            raise ScenarioError(f"no world {str(world)!r}; shipped: {', '.join(world_names())}")
    elif not world_path.is_absolute() and relative_to is not None:
        world_path = relative_to / world_path
    return world_path


def load_fleet_scenario(name_or_path: str | Path, world: str | Path | None = None) -> FleetScenario:
    """Read and check a fleet scenario: the schema, its world, and each agent against the world's vehicles.

    ``world`` (a shipped world's name or a file) replaces the scenario's world: the same team on another
    world with the same vehicle names, for example ``exp2a-features`` on ``exp2-paper-scale``.

    Raises
    ------
    ScenarioError
        One line naming the file and the field.
    """
    path = resolve_fleet_path(name_or_path)
    spec = validate(FleetScenarioSpec, read_mapping(path, ScenarioError), path, ScenarioError)
    where = "--world" if world is not None else f"{path}: world"
    try:
        world_path = resolve_world_path(spec.world if world is None else world,
                                        path.parent if world is None else None)
        world = load_scenario(world_path)
    except ScenarioError as err:
        raise ScenarioError(f"{where}: {err}") from None
    known = {v.name for v in world.vehicles} | {world.spec.target.name}
    for i, variant in enumerate(spec.variants):
        for j, agent in enumerate(variant.agents):
            where = f"{path}: variants[{i}].agents[{j}]"
            if agent.vehicle not in known:
                raise ScenarioError(f"{where}.vehicle: {agent.vehicle!r} is not in world "
                                    f"{world.name!r} (vehicles: {', '.join(sorted(known))})")
            is_target = agent.vehicle == world.spec.target.name
            if agent.role is not None and (agent.role in ("airship", "target")) != is_target:
                raise ScenarioError(f"{where}.role: {agent.vehicle} {'is the target' if is_target else 'has a camera'}"
                                    f"; its role is {'airship or target' if is_target else 'uav or ground-station'}, "
                                    f"not {agent.role!r}")
    return FleetScenario(spec, world, path, world_path)
