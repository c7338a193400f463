"""``python -m nidar_mi.assign``: the ``assign`` command (:mod:`nidar_mi.cli.assign`)."""

if __name__ == "__main__":
    import sys

    from nidar_mi.cli import early_signals

    early_signals.install()  # Ctrl-C and SIGTERM while the command imports

    from nidar_mi.cli.assign import main

    sys.exit(main())
