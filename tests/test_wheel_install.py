"""Installing as users of deepSI, tsfast and FMPy do: ``pip install`` of the built wheel (not an editable
checkout), with every extra, into a fresh virtual environment, then the demo (issue 24, item 17).

The wheel is built from a copy of the sources (``pip wheel --no-deps``), so nothing is written into the
checkout. The fresh environment downloads nothing: it reuses the packages this interpreter already has
(its site-packages without nnfmu itself, through a ``.pth`` file), and pip runs with ``--no-index``, so a
requirement that is not already there fails the test instead of being fetched; torch is pinned to the
version ``make setup`` installs. The demo runs with the test suite's tiny budget (the small valve data, 2
epochs; the whole pipeline: generate, train with the compiled free run, export, linear and physics FMUs,
fmpy scores), from a folder outside the checkout, so that ``import nnfmu`` finds the installed wheel.
"""

from __future__ import annotations

import os
import shutil
import site
import subprocess
import sys
import textwrap
import zipfile
from importlib import metadata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TORCH_PIN = "torch==2.13.0"  # as the Makefile installs it: never unpinned
_NOT_SHIPPED = (".pyc", ".so", ".pyd", ".dll", ".dylib")


def runtime_files() -> list[str]:
    """Every file of the package that is not Python source: what the package reads at run time (C sources
    and headers). Taken from git where the checkout is a repository (untracked scratch files do not count)."""
    try:
        listed = subprocess.run(["git", "ls-files", "nnfmu"], cwd=ROOT, capture_output=True, text=True, check=True)
        names = listed.stdout.split()
    except (OSError, subprocess.CalledProcessError):
        names = [p.relative_to(ROOT).as_posix() for p in (ROOT / "nnfmu").rglob("*") if p.is_file()]
    return sorted(n for n in names if not n.endswith(".py") and "__pycache__" not in n and not n.endswith(_NOT_SHIPPED))


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel of this checkout, built from a copy of its sources."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "nnfmu", src / "nnfmu", ignore=shutil.ignore_patterns("__pycache__", *("*" + s for s in
                                                                                               _NOT_SHIPPED)))
    isolation = []
    try:  # setuptools here: build with it; otherwise pip fetches it from the package registry
        import setuptools  # noqa: F401

        isolation = ["--no-build-isolation"]
    except ImportError:
        pass
    run = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", *isolation, "-q", "-w", str(tmp / "dist"),
                          "./src"], cwd=tmp, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-3000:]
    (built,) = (tmp / "dist").glob("nnfmu-*.whl")
    return built


def test_the_wheel_holds_every_file_the_package_reads_at_run_time(wheel):
    needed = runtime_files()
    assert "nnfmu/training/rollout.c" in needed and "nnfmu/export/csrc/nnfmu_fast.h" in needed
    assert any(n.startswith("nnfmu/export/templates/") for n in needed)
    shipped = set(zipfile.ZipFile(wheel).namelist())
    assert [n for n in needed if n not in shipped] == []


def _reused_site_packages(folder: Path) -> Path:
    """A folder of links to this interpreter's installed packages, without nnfmu (its editable install)."""
    folder.mkdir()
    for directory in site.getsitepackages():
        for entry in Path(directory).iterdir():
            if "nnfmu" not in entry.name.lower() and not (folder / entry.name).exists():
                (folder / entry.name).symlink_to(entry)
    return folder


TINY_DEMO = textwrap.dedent("""
    import sys
    import torch
    import nnfmu
    from nnfmu.training.rollout_library import library_or_none
    from nnfmu.study import Hyper, get_budget, run_demo

    print("nnfmu from", nnfmu.__file__)
    for stem in ("rollout", "window_rollout"):
        assert library_or_none(torch.float32, stem) is not None, stem + ".c did not compile"
    from nnfmu.ss.compiled import _library
    assert _library(torch.float32) is not None, "nnfmu/ss/state_loop.c did not compile"
    budget = get_budget("valve", "demo").replace(
        data_size="small", max_train=None, max_test=None, epochs=2, max_minutes=None,
        hyper={"gru": Hyper(hidden=8, batch_size=16)}, linear={"refine": False, "max_order": 4})
    run_demo(sys.argv[1], budget=budget, progress=False, echo=print)
""")


@pytest.mark.slow
def test_a_fresh_environment_installs_the_wheel_with_its_extras_and_runs_the_demo(wheel, tmp_path):
    extras = sorted(metadata.metadata("nnfmu").get_all("Provides-Extra"))  # every extra of pyproject.toml
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                             capture_output=True, text=True, check=True).stdout.strip()
    reused = _reused_site_packages(tmp_path / "reused")
    Path(purelib, "_nnfmu_test_reuse.pth").write_text(f"import site; site.addsitedir({str(reused)!r})\n")
    install = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-index",
                              f"nnfmu[{','.join(extras)}] @ {wheel.as_uri()}", TORCH_PIN],
                             capture_output=True, text=True)
    assert install.returncode == 0, install.stdout[-2000:] + install.stderr[-3000:]
    assert "Successfully installed nnfmu" in install.stdout
    work = tmp_path / "work"  # outside the checkout: `import nnfmu` must find the wheel, not the sources
    work.mkdir()
    (work / "tiny_demo.py").write_text(TINY_DEMO)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["NNFMU_CACHE_DIR"] = str(tmp_path / "cache")  # compile rollout.c afresh, from the wheel's copy
    helped = subprocess.run([str(venv / "bin" / "nnfmu"), "demo", "--help"], cwd=work, capture_output=True,
                            text=True, env=env)
    assert helped.returncode == 0 and "usage: nnfmu demo" in helped.stdout, helped.stderr[-2000:]
    demo = subprocess.run([str(python), "tiny_demo.py", "demo-output"], cwd=work, capture_output=True, text=True,
                          env=env, timeout=1200)
    assert demo.returncode == 0, demo.stdout[-2000:] + demo.stderr[-3000:]
    assert f"nnfmu from {purelib}" in demo.stdout
    assert "FMUs (FMI 2.0 co-simulation, standalone C)" in demo.stdout
    fmus = sorted(p.name for p in (work / "demo-output" / "fmus").glob("*.fmu"))
    assert fmus == ["gru-parallel.fmu", "gru-series-parallel.fmu", "linear.fmu", "physics.fmu"]
