"""Command-line tools (calibration and characterisation); each module exposes ``main(argv)``."""
