"""``python -m nidar_mi.reconstruct``: the ``reconstruct`` command (:mod:`nidar_mi.cli.reconstruct`)."""

if __name__ == "__main__":
    import sys

    from nidar_mi.cli import early_signals

    early_signals.install()  # Ctrl-C and SIGTERM while the command imports

    from nidar_mi.cli.reconstruct import main

    sys.exit(main())
