"""``python -m relaff_jax.cli``: the same as the ``relaff`` command."""
import sys

from relaff_jax.cli import main

sys.exit(main())
