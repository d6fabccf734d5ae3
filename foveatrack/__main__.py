import sys

from foveatrack.cli import main

sys.exit(main())
