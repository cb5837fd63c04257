"""``python -m flexmb`` is the ``flexmb`` command."""

import sys

from .cli import main

sys.exit(main())
