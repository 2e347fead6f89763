"""Regenerate the stored broadcast set: ``python -m ins_gnss_ros.gnss.ephemeris_data SRC OUT``."""
import sys

from . import main

sys.exit(main())
