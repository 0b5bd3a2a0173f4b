"""``python -m qrfield`` runs the command line (no subcommand opens the app)."""

import sys

from qrfield.cli import main

sys.exit(main())
