"""``python -m nidar_mi.reflectance_cue``: the ``reflectance_cue`` command
(:mod:`nidar_mi.cli.reflectance_cue`)."""

if __name__ == "__main__":
    import sys

    from nidar_mi.cli import early_signals

    early_signals.install()  # Ctrl-C and SIGTERM while the command imports

    from nidar_mi.cli.reflectance_cue import main

    sys.exit(main())
