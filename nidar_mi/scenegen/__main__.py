"""``python -m nidar_mi.scenegen``: the ``scenegen`` command (:mod:`nidar_mi.cli.scenegen`)."""

if __name__ == "__main__":
    import sys

    from nidar_mi.cli import early_signals

    early_signals.install()  # Ctrl-C and SIGTERM while the command imports

    from nidar_mi.cli.scenegen import main

    sys.exit(main())
