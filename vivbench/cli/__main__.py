import sys

from vivbench.cli import main

sys.exit(main())
