"""``python -m nidar_mi``: list the commands, or run one (:mod:`nidar_mi.cli`)."""

import sys

from nidar_mi.cli import early_signals, main  # the package imports its commands when run

early_signals.install()  # Ctrl-C and SIGTERM while the command imports

sys.exit(main())
