"""The `lagjax` command: `main` (scenes, run), the run itself, its figure, the demo."""

from lagjax.cli.command import main as main
