"""World commands of the ``evopose`` CLI: ``render`` (what a vehicle sees, or a whole dataset), ``develop`` (a dataset
developed again through another look), ``features`` (image -> points) and ``train-scorer`` (the front-end's mark
scorer from datasets).

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

#: An ``--out`` with one of these suffixes is one image; anything else is a dataset directory.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".webp")


def render_command(
    scenario: Annotated[str, typer.Argument(metavar="SCENARIO", show_default=False,
                                            help="Scenario file, or a shipped scenario name (exp1-airship, exp2).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="An image to write (X.png), or a dataset directory "
                                                          "(docs/datasets.md).")] = Path("frame.png"),
    frame: Annotated[int | None, typer.Option("--frame", "-f", min=0, help="Image: frame index (default: 0).")] = None,
    vehicle: Annotated[str | None, typer.Option(help="Image: vehicle whose camera renders (default: the "
                                                     "first).")] = None,
    truth: Annotated[Path | None, typer.Option(help="Image: ground-truth JSON (default: beside the PNG).")] = None,
    clean: Annotated[bool, typer.Option("--clean", help="Image: no noise, blur, lighting changes, distractors, "
                                                        "occluders.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the ground truth (a dataset: its summary) as "
                                                         "JSON.")] = False,
    engine: Annotated[str | None, typer.Option(help="Dataset: cycles (Blender, photoreal; `make photoreal`) or "
                                                    "opencv (default: cycles).")] = None,
    frames: Annotated[int | None, typer.Option(min=1, max=999_999, help="Dataset: frames per camera (default: "
                                                                        "the world's).")] = None,
    samples: Annotated[int | None, typer.Option(min=1, max=4096, help="Dataset: Cycles samples per pixel "
                                                                      "(default: 24).")] = None,
    cameras: Annotated[str | None, typer.Option(help="Dataset: comma-separated vehicles, e.g. H1,H2 (default: "
                                                     "all).")] = None,
    no_target: Annotated[bool, typer.Option("--no-target", help="Dataset: the world without its target "
                                                                "(absent-target frames).")] = False,
    force: Annotated[bool, typer.Option("--force", help="Dataset: render anew over an existing dataset of other "
                                                        "settings.")] = False,
    look: Annotated[str | None, typer.Option(help="Dataset: a named look over the world's camera model "
                                                  "(docs/camera-model.md: camera, agx, filmic, vivid-warm, ...).")] = None,
) -> None:
    """Render what a vehicle's camera sees at a frame with its ground truth (--out X.png), or a dataset of every
    camera's images, poses and truth (--out DIR)."""
    if out.suffix.lower() not in IMAGE_SUFFIXES:
        if frame is not None or vehicle is not None or truth is not None or clean:
            raise typer.BadParameter("--frame, --vehicle, --truth and --clean are for one image (--out X.png); "
                                     "a dataset takes --frames, --cameras", param_hint="--out")
        _render_dataset(scenario, out, engine=engine or "cycles", frames=frames, samples=samples or 24,
                        cameras=cameras, target=not no_target, force=force, as_json=as_json, look=look)
        return
    if (engine is not None or frames is not None or samples is not None or cameras is not None or no_target or force
            or look is not None):
        raise typer.BadParameter(f"--engine, --frames, --samples, --cameras, --no-target, --force and --look are for "
                                 f"a dataset directory, not an image ({out.suffix})", param_hint="--out")
    from agents.tools.world import render_to_files

    result = render_to_files(scenario, frame or 0, out, vehicle=vehicle, truth_path=truth, clean=clean)
    if as_json:
        print(json_line(result))
    else:
        Console().print(f"{result['image']}: {result['vehicle']} frame {result['frame']} "
                        f"(t = {result['time']:.2f} s), {len(result['marks'])} visible marks; "
                        f"truth in {result['truth']}")


def _render_dataset(world: str, out: Path, *, engine: str, frames: int | None, samples: int, cameras: str | None,
                    target: bool, force: bool, as_json: bool, look: str | None = None) -> None:
    """``--out DIR``: the dataset, with a progress bar per camera on stderr."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from scenarios.looks import LOOKS

    from agents.tools.render_dataset import ENGINES, render_dataset

    if engine not in ENGINES:
        raise typer.BadParameter(f"expected one of {', '.join(ENGINES)}, got {engine!r}", param_hint="--engine")
    if look is not None and look not in LOOKS:
        raise typer.BadParameter(f"unknown look {look!r} (looks: {', '.join(LOOKS)})", param_hint="--look")
    names = None
    if cameras is not None:
        names = [c.strip() for c in cameras.split(",")]
        if not all(names):
            raise typer.BadParameter(f"expected comma-separated vehicle names, got {cameras!r}", param_hint="--cameras")
    console = Console(stderr=True)
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=console, transient=False) as bar:
        tasks: dict[str, int] = {}

        def on_image(event: dict) -> None:
            camera = event["camera"]
            if camera not in tasks:
                tasks[camera] = bar.add_task(f"{camera} frames", total=event["frames"])
            bar.update(tasks[camera], completed=event["frame"] + 1)

        summary = render_dataset(world, out, engine=engine, frames=frames, samples=samples, cameras=names,
                                 target=target, force=force, progress=on_image, look=look)
    if as_json:
        print(json_line(summary))
    else:
        per = summary["seconds_per_image"]
        Console().print(f"{summary['dataset']}: {summary['world']}, {summary['complete_frames']} of {summary['frames']} "
                        f"frames x {', '.join(summary['cameras'])} ({summary['engine']}); "
                        f"{summary['images_rendered']} images rendered"
                        + (f", {per:.1f} s each" if per else "") + f" in {summary['wall_seconds']:.0f} s")


def develop_command(
    source: Annotated[Path, typer.Argument(metavar="SRC", show_default=False,
                                           help="A rendered dataset that kept its raw EXRs (<camera>/raw/).")],
    look: Annotated[str, typer.Option("--look", show_default=False,
                                      help="The look (docs/camera-model.md): camera, agx, agx-punchy, filmic, "
                                           "vivid-warm, flat-cool, hable-faded, gamma-dark.")],
    out: Annotated[Path, typer.Option("--out", "-o", show_default=False, help="The new dataset directory.")],
    force: Annotated[bool, typer.Option("--force", help="Replace a dataset already at --out.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as one JSON line.")] = False,
) -> None:
    """Develop a rendered dataset again through another camera look, from its raw EXRs (no rendering): same
    truth, poses and sensor noise, new images."""
    from agents.tools.develop_dataset import develop_dataset

    summary = develop_dataset(source, out, look, force=force)
    if as_json:
        print(json_line(summary))
    else:
        Console().print(f"{summary['dataset']}: {summary['source']} through the look {summary['look']!r}, "
                        f"{summary['frames']} frames x {', '.join(summary['cameras'])}; "
                        f"{summary['images_developed']} images in {summary['wall_seconds']:.1f} s")


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


def train_scorer_command(
    datasets: Annotated[list[Path], typer.Argument(metavar="DATASET...", show_default=False,
                                                   help="Dataset directories with truth (docs/datasets.md).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="The scorer's JSON file.")] = Path("mark_scorer.json"),
    l2: Annotated[float, typer.Option(min=0.0, max=1e6, help="L2 penalty on the weights (30: the least held-out "
                                                             "log-loss on the training worlds).")] = 30.0,
    looks: Annotated[int, typer.Option(min=0, max=50, help="Also develop each frame of a dataset with raw EXRs "
                                                          "through this many random camera looks.")] = 0,
    corner_looks: Annotated[int, typer.Option(min=0, max=50, help="... and through this many looks at the edges of "
                                                                  "the random looks' ranges.")] = 0,
    seed: Annotated[int, typer.Option(help="Seed of the random looks.")] = 0,
    scale: Annotated[str, typer.Option(help="paper: the mark scorer of 2-4 px marks; telephoto: the context model "
                                            "of marks of 3 px and more (vision/mark_context.json).")] = "paper",
    keep: Annotated[float | None, typer.Option(min=0.5, max=0.999, help="The threshold keeps this share of the marks "
                                               "(held out by geometry); default: the hand-set bars' share.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Fit the contrast front-end's mark scorer (2-4 px marks) or context model (--scale telephoto) on rendered
    datasets with truth."""
    from vision.train_scorer import SCALE_MATCH_PX, train

    if scale not in SCALE_MATCH_PX:
        raise typer.BadParameter(f"expected one of {', '.join(SCALE_MATCH_PX)}, got {scale!r}", param_hint="--scale")
    console = Console(stderr=True)
    summary = train(datasets, out, l2=l2, progress=None if as_json else console.print, looks=looks, seed=seed,
                    scale=scale, keep=keep, corner_looks=corner_looks)
    if as_json:
        print(json_line(summary))
        return
    Console().print(f"{summary['out']}: {summary['candidates']} candidates, {summary['marks']} marks (the hand-set "
                    f"bars find {summary['bars_keep']:.1%}); threshold {summary['threshold']:.2f} keeps "
                    f"{summary['marks_kept']:.1%} of the marks at precision {summary['precision']:.1%} (on the "
                    f"fitting data)")


def register(app: typer.Typer) -> None:
    """Add the world commands to the CLI ``app``."""
    app.command("render")(render_command)
    app.command("develop")(develop_command)
    app.command("features")(features_command)
    app.command("train-scorer")(train_scorer_command)
