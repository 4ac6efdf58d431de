"""`python -m lagjax.cli` runs the `lagjax` command."""

from lagjax.cli.command import main

raise SystemExit(main())
