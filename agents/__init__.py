"""Everything that runs: one sub-package per room (docs/architecture.md).

- :mod:`agents.cli`: the ``evopose`` command line, thin typer commands;
- :mod:`agents.transport`: the Zenoh session and the fleet bus;
- :mod:`agents.vehicle`: one vehicle of the fleet (clock, camera, team views, roles, the per-frame step);
- :mod:`agents.tools`: fleet and world tools (router, meter, publish, listen, render, features);
- :mod:`agents.experiments`: scenarios run as processes, results, the report, compose files;
- :mod:`agents.problem`: the pose-problem file contract (docs/design.md §3) and solving from it.
"""
