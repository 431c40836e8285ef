"""Service functions behind the CLI commands: each does one command's work and returns plain data."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from evopose import solve
from evopose.fitness import FitnessKind

from .problem_file import load_problem, solution_to_dict


def solve_file(path: str | Path, *, seed: int | None = None, time_budget: float | None = None,
               fitness: FitnessKind | None = None) -> dict:
    """Solve the pose-problem file at ``path`` (DESIGN.md §3) and return the output object.

    ``seed``, ``time_budget`` and ``fitness`` override the file's ``seed`` and ``options`` when given.

    Raises
    ------
    ProblemFileError
        The file is unreadable or malformed.
    """
    problem, options, file_seed = load_problem(path)
    overrides = {name: value for name, value in (("time_budget", time_budget), ("fitness", fitness))
                 if value is not None}
    options = dataclasses.replace(options, **overrides)
    solution = solve(problem, options, seed=file_seed if seed is None else seed)
    return solution_to_dict(solution)
