"""Application layer: the ``femodes`` command line, case files and sweeps."""
