from flexff.cli import main

raise SystemExit(main())
