"""Every ```python block of README.md and docs/guide.md runs, so the guide cannot
drift from the code.

The blocks run in order (the README's, then the guide's) in one namespace, as a reader would paste them
into one session (a later block may use an earlier block's imports), with matplotlib
on its file-only Agg backend so `plt.show()` returns at once. Nothing is skipped.
"""

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # plt.show() is a no-op; no display needed
import matplotlib.pyplot as plt
import pytest

# The guide's examples run whole, like the notebooks: CI's second step
# (`bash tasks.sh integration`).
pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", ROOT / "docs" / "guide.md"]
FENCE = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)
ANY_FENCE = re.compile(r"^```.*?^```", re.MULTILINE | re.DOTALL)


def _blocks() -> list[tuple[str, str]]:
    """(the heading above the block, its code) for every ```python block."""
    blocks = []
    for page in PAGES:
        text = page.read_text()
        for match in FENCE.finditer(text):
            prose = ANY_FENCE.sub("", text[: match.start()])  # no comments as headings
            headings = re.findall(r"^#+ (.+)$", prose, re.MULTILINE)
            heading = headings[-1] if headings else "top"
            blocks.append((f"{page.name}: {heading}", match.group(1)))
    return blocks


BLOCKS = _blocks()


def test_the_readme_has_python_blocks():
    assert len(BLOCKS) >= 2
    assert any("first look" in heading.lower() for heading, _ in BLOCKS)


def test_readme_blocks_run_in_order():
    namespace: dict = {"__name__": "__readme__"}
    for number, (heading, code) in enumerate(BLOCKS, start=1):
        try:
            exec(compile(code, f"README.md, block {number}", "exec"), namespace)
        except Exception as error:
            raise AssertionError(
                f"block {number} (under '{heading}') failed: {error!r}"
            ) from error
        finally:
            plt.close("all")
