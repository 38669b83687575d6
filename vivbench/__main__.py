"""``python -m vivbench``: the same command line as the ``vivbench`` script."""

from vivbench.cli import main

raise SystemExit(main())
