import sys

from tpvp.cli import main

sys.exit(main())
