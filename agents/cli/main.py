"""The ``evopose`` command line: thin typer commands that call one service function each.

Errors become exit codes only here: a malformed input or a bad argument prints one line
``error: <message>`` on stderr and exits with code 2, never a traceback.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from agents.cli import agent as agent_commands
from agents.cli import bridges as bridge_commands
from agents.cli import fleet as fleet_commands
from agents.cli import scenario as scenario_commands
from agents.cli import world as world_commands
from agents.cli.options import json_line

#: The fitness kinds of evopose.fitness.FitnessKind: mutual (the default), robust, or the paper's eq. (1).
FITNESS_KINDS = ("mutual", "robust", "paper")

#: Exit code of a malformed input or a bad command-line argument.
USAGE_ERROR = 2

app = typer.Typer(name="evopose", add_completion=False, pretty_exceptions_enable=False)


@app.callback()
def evopose() -> None:
    """EvoPose Fleet: cooperative 6-DOF pose estimation by evolutionary search."""


fleet_commands.register(app)
agent_commands.register(app)
scenario_commands.register(app)
scenario_commands.register_report(app)
world_commands.register(app)
bridge_commands.register(app)


@app.command("solve")
def solve_command(
    problem: Annotated[Path | None, typer.Argument(metavar="[PROBLEM]", show_default=False,
                                                   help="Pose-problem file, YAML or JSON (docs/design.md §3).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of a table.")] = False,
    seed: Annotated[int | None, typer.Option(min=0, help="Random seed; overrides the file's seed.")] = None,
    time_budget: Annotated[float | None, typer.Option(min=0, help="Wall-time budget in seconds.")] = None,
    fitness: Annotated[str | None, typer.Option(help="Fitness: mutual (default), robust, or the paper's eq. (1) "
                                                     "(paper).")] = None,
    image: Annotated[Path | None, typer.Option(help="Solve from this image instead of a problem file "
                                                    "(needs --model and --camera).")] = None,
    model: Annotated[str | None, typer.Option(help="Target-model file (or shipped name) for --image.")] = None,
    camera: Annotated[Path | None, typer.Option(help="Camera file for --image: the problem file's camera fields "
                                                     "or a ROS camera_info YAML.")] = None,
    features: Annotated[str, typer.Option(help="Points --image gives: auto or contrast (the model's colour marks "
                                               "by their contrast, any camera look), marks (preset hue bands: "
                                               "flat-coloured drawings) or corners (a chessboard's inner "
                                               "corners).")] = "auto",
    overlay: Annotated[Path | None, typer.Option(help="Write a PNG of the first view with its points and "
                                                      "the model projected at the estimate.")] = None,
) -> None:
    """Find the pose of the model in the views of PROBLEM (or in one --image)."""
    from agents.problem.solve import solve_file, solve_image

    if fitness is not None and fitness not in FITNESS_KINDS:
        raise typer.BadParameter(f"must be one of {', '.join(FITNESS_KINDS)}, got {fitness!r}", param_hint="--fitness")
    if image is not None:
        if problem is not None or model is None or camera is None:
            raise typer.BadParameter("--image needs --model and --camera, and no PROBLEM", param_hint="--image")
        result = solve_image(image, model, camera, seed=seed, time_budget=time_budget, fitness=fitness,
                             overlay=overlay, features=features)
    elif problem is None:
        raise typer.BadParameter("Missing argument 'PROBLEM' (or --image with --model and --camera).",
                                 param_hint="PROBLEM")
    else:
        result = solve_file(problem, seed=seed, time_budget=time_budget, fitness=fitness, overlay=overlay)
    if as_json:
        print(json_line(result))
    else:
        Console().print(solution_table(result))


def solution_table(result: dict) -> Table:
    """A short human-readable table of a solve result (position in metres, angles in degrees)."""
    pose = result["pose"]
    table = Table(title="EvoPose solution", show_header=False)
    table.add_column(style="bold")
    table.add_column(justify="right")
    for name in ("x", "y", "z"):
        table.add_row(name, f"{pose[name]:.3f} m")
    for name in ("roll", "pitch", "yaw"):
        table.add_row(name, f"{math.degrees(pose[name]):.2f}°")
    table.add_row("fitness", f"{result['fitness']:.4g}")
    table.add_row("generations", str(result["generations"]))
    table.add_row("time", f"{result['seconds']:.2f} s")
    table.add_row("converged", f"{'yes' if result['converged'] else 'no'} ({result['stop_reason']})")
    return table


def _fail(message: str, code: int) -> int:
    print(f"error: {' '.join(message.split())}", file=sys.stderr)
    return code


def _usage_error() -> type[BaseException]:
    """The root of the errors that mean a bad input or argument (every package's derive from it). Imported only on
    the error path: ``--help`` stays light."""
    from evopose_errors import EvoPoseError

    return EvoPoseError


def main(argv: list[str] | None = None) -> int:
    """Run the CLI on ``argv`` (default: ``sys.argv[1:]``) and return the exit code."""
    try:
        code = app(args=argv, prog_name="evopose", standalone_mode=False)
    except typer.TyperException as err:
        return _fail(err.format_message(), err.exit_code)
    except typer.Abort:
        return _fail("aborted", 1)
    except MemoryError:
        return _fail("out of memory: the input is too large (see the documented problem-size limits)", USAGE_ERROR)
    except RecursionError:
        return _fail("input nested too deeply", USAGE_ERROR)
    except Exception as err:  # noqa: BLE001 - one line for a usage error, the traceback for a bug
        if isinstance(err, _usage_error()):
            return _fail(str(err), USAGE_ERROR)
        raise
    return code if isinstance(code, int) else 0


if __name__ == "__main__":
    sys.exit(main())
