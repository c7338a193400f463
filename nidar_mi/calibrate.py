"""``python -m nidar_mi.calibrate``: the ``calibrate`` command (:mod:`nidar_mi.cli.calibrate`)."""

if __name__ == "__main__":
    import sys

    from nidar_mi.cli import early_signals

    early_signals.install()  # Ctrl-C and SIGTERM while the command imports

    from nidar_mi.cli.calibrate import main

    sys.exit(main())
