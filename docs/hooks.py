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


# README.md is the site's home page (docs/index.md stands for it); its links point
# from the repository root, so on the site they are rewritten to the docs pages.
_README_LINKS = {
    "](docs/guide.md)": "](guide.md)",
    "](docs/performance.md)": "](performance.md)",
    "](CHANGELOG.md)": "](changelog.md)",
    "](CONTRIBUTING.md)": "](contributing.md)",
}


def on_page_markdown(markdown: str, page: Any, config: Any, **_: Any) -> str:
    if page.file.src_uri != "index.md":
        return markdown
    markdown = (Path(config["docs_dir"]).parent / "README.md").read_text()
    for old, new in _README_LINKS.items():
        markdown = markdown.replace(old, new)
    return markdown
