"""``python -m nidar_mi.drive``: the ``drive`` command (:mod:`nidar_mi.cli.drive`)."""

if __name__ == "__main__":
    import sys

    from nidar_mi.cli import early_signals

    early_signals.install()  # Ctrl-C and SIGTERM while the command imports

    from nidar_mi.cli.drive import main

    sys.exit(main())
