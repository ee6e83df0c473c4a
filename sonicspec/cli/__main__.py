"""``python -m sonicspec.cli``: the ``sonicspec`` command."""

import sys

from sonicspec.cli import main

sys.exit(main())
