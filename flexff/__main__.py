"""`python -m flexff`: the command line (flexff.cli), as the `flexff` script runs it."""

from flexff.cli import main

raise SystemExit(main())
