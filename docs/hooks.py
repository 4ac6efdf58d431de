"""MkDocs hook: the "Notebooks" section of the nav lists every notebook in notebooks/.

A notebook added to the repository appears on the site without editing mkdocs.yml
(and `mkdocs build --strict` cannot fail because the nav forgot one). Each entry is
titled by the notebook's first Markdown heading, without its "N · " number.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

SECTION = "Notebooks"


def _title(notebook: Path) -> str:
    cells = json.loads(notebook.read_text())["cells"]
    for cell in cells:
        if cell["cell_type"] == "markdown":
            for line in "".join(cell["source"]).splitlines():
                if line.startswith("#"):
                    return re.sub(r"^#+\s*(\d+\s*·\s*)?", "", line).strip()
    return notebook.stem


def on_config(config: Any) -> Any:
    docs = Path(config["docs_dir"])
    notebooks = sorted((docs / "notebooks").glob("*.ipynb"))
    entries = [{_title(path): f"notebooks/{path.name}"} for path in notebooks]
    for item in config["nav"]:
        if isinstance(item, dict) and SECTION in item:
            item[SECTION] = entries
            return config
    config["nav"].append({SECTION: entries})
    return config
