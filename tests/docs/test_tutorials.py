"""The tutorials run as written, with the public API only, and their notebooks match their pages."""

import importlib.util
import json
import re

import matplotlib
import pytest

from tests.conftest import REPO

pytestmark = pytest.mark.heavy  # end-to-end runs of a minute or more


TUTORIALS = REPO / "docs" / "tutorials"
_spec = importlib.util.spec_from_file_location("make_notebooks", TUTORIALS / "make_notebooks.py")
make_notebooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_notebooks)


def _code(page):
    return [text for kind, text in make_notebooks.cells((TUTORIALS / page).read_text()) if kind == "code"]


@pytest.mark.parametrize("page", sorted(p.name for p in TUTORIALS.glob("*.md")))
def test_tutorials_use_only_the_public_api(page):
    # The public namespaces are `dynax`, `dynax.control` and `dynax.synthetic`; `dynax.internal` and the
    # underscored modules are not for tutorials.
    private = re.findall(
        r"(?:from|import)\s+dynax\.(?!control\b|synthetic\b)\w+|dynax\._\w+|dynax\.internal\b",
        (TUTORIALS / page).read_text(),
    )
    assert not private, f"{page} reaches beyond the public API: {private}"


@pytest.mark.parametrize("page", make_notebooks.EXECUTED)
def test_notebook_matches_its_page(page):
    notebook = json.loads((TUTORIALS / page).with_suffix(".ipynb").read_text())
    assert notebook == make_notebooks.to_notebook((TUTORIALS / page).read_text()), (
        f"docs/tutorials/{page} changed: run python docs/tutorials/make_notebooks.py")


# The quadrotor page fits ten minutes of flight (about 50 s): it runs in the slow suite.
@pytest.mark.parametrize(
    "page",
    [pytest.param(p, marks=pytest.mark.slow) if p == "quadrotor_flights.md" else p for p in make_notebooks.EXECUTED],
)
def test_tutorial_runs_top_to_bottom(page, datasets, monkeypatch, tmp_path):
    monkeypatch.chdir(TUTORIALS)  # where Jupyter starts the notebook; the pages find ../shared/datasets/ from there
    matplotlib.rcParams["figure.max_open_warning"] = 0
    namespace = {"__name__": "__tutorial__"}
    for i, block in enumerate(_code(page)):
        try:
            exec(compile(block, f"{page}, code block {i + 1}", "exec"), namespace)
        except Exception as e:
            raise AssertionError(f"{page}, code block {i + 1} failed: {e!r}\n{block}") from e


@pytest.mark.slow  # about 40 s: a Jupyter kernel; the quick suite runs the same page's code in process
def test_notebook_runs_in_a_jupyter_kernel(datasets, tmp_path):
    """What a user does: open the notebook in Jupyter and run all cells. Executed by a real
    IPython kernel (nbclient), from the notebook's folder, with this interpreter's packages."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    notebook = nbformat.read(TUTORIALS / "first_steps.ipynb", as_version=4)
    client = nbclient.NotebookClient(
        notebook, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(TUTORIALS)}}
    )
    client.execute()
    errors = [o for c in notebook.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"]
    assert not errors, errors
    assert sum(c.cell_type == "code" for c in notebook.cells) >= 3
