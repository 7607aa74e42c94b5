"""The ``navkit`` command line: thin commands over the library (see :mod:`navkit.cli.main`)."""
