"""``python -m nidar_mi.pseudo_nir``: the ``pseudo_nir`` command (:mod:`nidar_mi.cli.pseudo_nir`)."""

if __name__ == "__main__":
    import sys

    from nidar_mi.cli import early_signals

    early_signals.install()  # Ctrl-C and SIGTERM while the command imports

    from nidar_mi.cli.pseudo_nir import main

    sys.exit(main())
