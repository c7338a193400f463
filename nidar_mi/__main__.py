"""``python -m nidar_mi``: list the commands, or run one (:mod:`nidar_mi.cli`)."""

import sys

from nidar_mi.cli import main

sys.exit(main())
