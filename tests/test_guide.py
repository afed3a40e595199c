"""The guide's and the README's code blocks run as written: each page's ```python blocks in
order, in one namespace, from an empty folder (what a reader who copies them gets). Their
printed numbers are the pages' own business; this test catches an example that an API change
broke."""
import contextlib
import io
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted(str(path.relative_to(ROOT)) for path in [ROOT / "README.md",
                                                        *(ROOT / "docs" / "guide").glob("*.md")]
               if "```python" in path.read_text())
NEEDS_SICONOS = {"docs/guide/siconos-peer.md"}


def code_blocks(page: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", (ROOT / page).read_text(), re.S)


def test_the_pages_with_code_are_found():
    assert {"README.md", "docs/guide/adding-a-law.md", "docs/guide/adding-a-solver.md",
            "docs/guide/first-simulation.md"} <= set(PAGES)


@pytest.mark.parametrize("page", PAGES)
def test_a_pages_code_blocks_run(page, tmp_path, monkeypatch):
    if page in NEEDS_SICONOS:
        from lubcontact.solvers import siconos_peer

        if not siconos_peer.siconos_status().available:
            pytest.skip("Siconos numerics is not installed")
        (tmp_path / "lubcontact").symlink_to(ROOT / "lubcontact")   # the page reads its data
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "guide"}
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        for number, block in enumerate(code_blocks(page), start=1):
            exec(compile(block, f"{page} (block {number})", "exec"), namespace)
