"""``python -m wavemesh`` is the ``wavemesh`` command."""

import sys

from wavemesh.cli import main

sys.exit(main())
