"""``python -m sensornet`` is the ``sensornet`` command."""

import sys

from sensornet.cli import main

sys.exit(main())
