"""``python -m agents.cli``: the ``evopose`` command."""

import sys

from agents.cli.main import main

sys.exit(main())
