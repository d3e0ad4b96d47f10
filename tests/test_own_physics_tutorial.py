"""docs/own-physics.md, run as written, with a small budget: every ``nnfmu`` command of the page in order
(the user's model file, its FMU, generated data, the grey-box fit, the hybrid on the fit, the neural ODE and
their FMUs), then the page's fmpy example (co-simulation and Model Exchange with CVode).

The budget options appended to the page's commands are the only change: ``--size small`` for the data,
few evaluations for the fit, two epochs on short windows for the trainings. The model file is the
repository's ``examples/two_tanks.py``, copied into the working folder as a user would have it.
"""

from __future__ import annotations

import re
import shlex
import shutil
from pathlib import Path

import fmpy
import numpy as np
import pytest

from nnfmu.cli import main

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "own-physics.md"
#: per command: the options that make it small (appended to the page's own)
SMALL = {"generate": ["--size", "small"], "fit": ["--max-evaluations", "5", "--window", "100", "--quiet"],
         "train": ["--epochs", "2", "--truncate", "50", "--quiet"]}


def page_commands() -> list[list[str]]:
    """The page's shell commands (indented ``nnfmu ...`` lines), in order, without the leading ``nnfmu``."""
    lines = re.findall(r"^    nnfmu (.+)$", PAGE.read_text(), flags=re.MULTILINE)
    return [shlex.split(line) for line in lines]


def page_python(marker: str) -> str:
    """The page's first ```python block that contains ``marker``."""
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.DOTALL)
    return next(b for b in blocks if marker in b)


@pytest.fixture(scope="module")
def tutorial(tmp_path_factory):
    """The page's commands run in a fresh folder; returns the folder."""
    work = tmp_path_factory.mktemp("own-physics")
    (work / "examples").mkdir()
    shutil.copy(ROOT / "examples" / "two_tanks.py", work / "examples" / "two_tanks.py")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(work)
        for argv in page_commands():
            assert main(argv + SMALL.get(argv[0], [])) == 0, argv
    return work


def test_the_page_walks_the_whole_workflow():
    commands = [argv[0] for argv in page_commands()]
    for command in ("info", "physics-fmu", "generate", "fit", "train", "export"):
        assert command in commands
    assert commands.index("generate") < commands.index("fit") < commands.index("train")


def test_every_command_of_the_page_runs_and_writes_what_it_names(tutorial):
    for argv in page_commands():
        if "-o" in argv:
            assert (tutorial / argv[argv.index("-o") + 1]).exists(), argv


def test_the_fit_result_is_a_model_with_the_free_parameters_fitted(tutorial):
    import json

    from nnfmu.physics import resolve_physics

    doc = json.loads((tutorial / "tanks_fit.json").read_text())
    fitted = {name: p["value"] for name, p in doc["fit"]["parameters"].items()}
    assert all(p["std_error"] > 0 for p in doc["fit"]["parameters"].values())
    assert set(fitted) == {"a1", "a2", "k_p"}  # A1 and A2 are declared fixed
    system = resolve_physics(str(tutorial / "tanks_fit.json"))
    assert {v.name: v.start for v in system.parameters if v.name in fitted} == pytest.approx(fitted)


def test_the_pages_fmpy_example_runs_both_interfaces(tutorial, monkeypatch):
    monkeypatch.chdir(tutorial)
    scope: dict = {}
    exec(page_python("fmpy.simulate_fmu"), scope)  # noqa: S102 - the page's own example
    cs, me = scope["cs"], scope["me"]
    assert len(cs) == len(me) == 600 and np.isfinite(cs["h2"]).all() and np.isfinite(me["h2"]).all()
    assert cs["h2"].max() > 0.05  # the pump at 8 V fills the tanks
    for fmu in ("two_tanks.fmu", "tanks_hybrid.fmu", "tanks_node.fmu"):
        assert fmpy.validation.validate_fmu(str(tutorial / fmu)) == [], fmu
        md = fmpy.read_model_description(str(tutorial / fmu))
        assert md.coSimulation is not None and md.modelExchange is not None, fmu
