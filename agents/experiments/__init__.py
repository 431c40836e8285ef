"""Experiments: fleet scenarios run as processes, their results, the report beside the paper, and compose files.

The package's face holds only the defaults the CLI shows in its help (so ``--help`` imports nothing heavy).
"""

#: Where a scenario's fleet can be reached from outside while it runs.
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
#: Image of every docker-compose service.
DEFAULT_IMAGE = "evopose-fleet"
#: The credentials directory of a secure compose file, relative to the file.
DEFAULT_CREDENTIALS = "credentials"
