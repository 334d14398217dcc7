"""``python -m robofabric``: the same as the ``robofabric`` command."""

import sys

from robofabric.cli import main

sys.exit(main())
