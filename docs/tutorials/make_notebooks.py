"""Write each executed tutorial (`*.md` here) as a Jupyter notebook beside it: `python docs/tutorials/make_notebooks.py`.

The Markdown page is the source; every ```python block becomes a code cell, the prose between
them markdown cells. `make test` checks that the notebooks match their pages and executes the code.
"""

import json
import pathlib
import re

HERE = pathlib.Path(__file__).resolve().parent
EXECUTED = ("first_steps.md", "dfki_simulation.md", "quadrotor_flights.md")  # the tutorials that run in make test, top to bottom
_BLOCK = re.compile(r"^```python\n(.*?)^```\n", re.S | re.M)


def cells(markdown: str) -> list[tuple[str, str]]:
    """The page as `(kind, text)` cells, kind `"markdown"` or `"code"`, in order."""
    out, position = [], 0
    for match in _BLOCK.finditer(markdown):
        prose = markdown[position : match.start()].strip()
        if prose:
            out.append(("markdown", prose))
        out.append(("code", match.group(1).rstrip("\n")))
        position = match.end()
    if markdown[position:].strip():
        out.append(("markdown", markdown[position:].strip()))
    return out


def to_notebook(markdown: str) -> dict:
    """A minimal nbformat-4 notebook of the page (no outputs)."""

    def cell(i, kind, text):
        # nbformat 4.5 requires an id per cell; the position keeps the file reproducible
        c = {"cell_type": kind, "id": f"cell-{i}", "metadata": {}, "source": text.splitlines(keepends=True)}
        if kind == "code":
            c.update(execution_count=None, outputs=[])
        return c

    return {
        "cells": [cell(i, kind, text) for i, (kind, text) in enumerate(cells(markdown))],
        "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
                     "language_info": {"name": "python"}},
        "nbformat": 4,
        "nbformat_minor": 5,
    }


if __name__ == "__main__":
    for name in EXECUTED:
        page = HERE / name
        target = page.with_suffix(".ipynb")
        target.write_text(json.dumps(to_notebook(page.read_text()), indent=1) + "\n")
        print(f"wrote {target}")
