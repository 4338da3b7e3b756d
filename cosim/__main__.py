"""``python -m feeddrive.cosim``: the same as the ``cosim`` command."""
import sys

from feeddrive.cosim.cli import main

sys.exit(main())
