import sys

from gatmo.cli import main

sys.exit(main())
