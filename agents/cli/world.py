"""World commands of the ``evopose`` CLI: ``render`` (what a vehicle sees) and ``features`` (image -> points).

Registered on :data:`agents.cli.main.app`; thin commands that call one service function each
(:mod:`agents.tools.world`). Input problems raise :class:`scenarios.errors.WorldError`, which
``agents.cli.main.main`` turns into one ``error: ...`` line and exit code 2.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from agents.cli.options import json_line


def render_command(
    scenario: Annotated[str, typer.Argument(metavar="SCENARIO", show_default=False,
                                            help="Scenario file, or a shipped scenario name (exp1-airship, exp2).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="PNG to write.")] = Path("frame.png"),
    frame: Annotated[int, typer.Option("--frame", "-f", min=0, help="Frame index.")] = 0,
    vehicle: Annotated[str | None, typer.Option(help="Vehicle whose camera renders (default: the first).")] = None,
    truth: Annotated[Path | None, typer.Option(help="Ground-truth JSON (default: beside the PNG).")] = None,
    clean: Annotated[bool, typer.Option("--clean", help="No noise, blur, lighting changes, distractors, "
                                                        "occluders.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the ground truth as JSON.")] = False,
) -> None:
    """Render what a vehicle's camera sees at a frame, with its ground truth (target pose, visible marks)."""
    from agents.tools.world import render_to_files

    result = render_to_files(scenario, frame, out, vehicle=vehicle, truth_path=truth, clean=clean)
    if as_json:
        print(json_line(result))
    else:
        Console().print(f"{result['image']}: {result['vehicle']} frame {result['frame']} "
                        f"(t = {result['time']:.2f} s), {len(result['marks'])} visible marks; "
                        f"truth in {result['truth']}")


def features_command(
    image: Annotated[Path, typer.Argument(metavar="IMAGE", show_default=False, help="Image file (PNG, JPEG).")],
    model: Annotated[str | None, typer.Option(help="Model file (or shipped name) whose mark colours to find; "
                                                   "default: any saturated hue.")] = None,
    colours: Annotated[str | None, typer.Option(help="Comma-separated hue names to find (red, orange, yellow, "
                                                     "chartreuse, green, spring, cyan, azure, blue, violet, "
                                                     "magenta, rose); overrides --model.")] = None,
    corners: Annotated[bool, typer.Option("--corners", help="Shi-Tomasi corners instead of colour marks.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Extract the feature points of an image (colour marks, or corners)."""
    from agents.tools.world import image_features

    names = [c.strip() for c in colours.split(",") if c.strip()] if colours else None
    result = image_features(image, model=model, colours=names, corners=corners)
    if as_json:
        print(json_line(result))
        return
    console = Console()
    console.print(f"{result['image']}: {result['count']} points ({result['method']})")
    for i, (u, v) in enumerate(result["points"]):
        label = f"  {result['colours'][i]}" if "colours" in result else ""
        console.print(f"{u:9.2f} {v:9.2f}{label}")


def register(app: typer.Typer) -> None:
    """Add the world commands to the CLI ``app``."""
    app.command("render")(render_command)
    app.command("features")(features_command)
