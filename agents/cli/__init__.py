"""The ``evopose`` command line: thin typer commands; heavy modules are imported inside the command that needs them."""

from agents.cli.main import app, main

__all__ = ["app", "main"]
