"""``python -m nidar_mi.evaluate``: the ``evaluate`` command (:mod:`nidar_mi.cli.evaluate`)."""

if __name__ == "__main__":
    import sys

    from nidar_mi.cli import early_signals

    early_signals.install()  # Ctrl-C and SIGTERM while the command imports

    from nidar_mi.cli.evaluate import main

    sys.exit(main())
