"""``python -m lawn_cli``: the ``lawn`` command."""

import sys

from . import main

sys.exit(main())
