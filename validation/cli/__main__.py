"""``python -m validation.cli``: the ``flexarm`` program."""
import sys

from . import main

sys.exit(main())
