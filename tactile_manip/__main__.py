import sys

from tactile_manip.cli import main

sys.exit(main())
