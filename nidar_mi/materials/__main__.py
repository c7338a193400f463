"""``python -m nidar_mi.materials``: the ``materials`` command (:mod:`nidar_mi.cli.materials`)."""

if __name__ == "__main__":
    import sys

    from nidar_mi.cli import early_signals

    early_signals.install()  # Ctrl-C and SIGTERM while the command imports

    from nidar_mi.cli.materials import main

    sys.exit(main())
