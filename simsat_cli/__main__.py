"""``python -m simsat_cli``: the ``simsat`` command."""
import sys

from simsat_cli import main

sys.exit(main())
