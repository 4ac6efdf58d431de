"""`python -m lagjax.cli` runs the `lagjax` command."""

import sys

from lagjax.cli.command import main

if __name__ == "__main__":  # importing the module (pkgutil walks) runs nothing
    sys.exit(main())
