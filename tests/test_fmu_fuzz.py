"""The FMU binaries against hostile FMU states and pointers, driven from C (tests/c/fuzz_driver.c).

- over 10,000 serialized states (byte flips, random payloads behind a valid header, crafted fields such as
  a sample count of -4e12 with a step limit of 9e18 or a mode of 0x7fffffff, wrong sizes): every broken
  one is refused with a logged Error, and the instance goes on with its old state;
- NULL for every pointer argument of every FMI 2 and FMI 3 function an importer may call, a call on a
  freed instance, a double free, and fmusim 0.0.39's freeFMUState(state itself): an Error with a message
  (or a call that works), never a crash or a hang;

on FMI 2 and FMI 3 binaries, co-simulation and Model Exchange. The driver runs the cases in forked
children under alarm(), so a crash or a hang fails the test and names the case.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from fmu_cases import MODELS, FMICallException, Instance, built_fmu, excitation, unzipped
from test_fmu_me_events import bounded_pendulum

from nnfmu.cbuild import run_compiler
from nnfmu.export.fmu import fmi_header_dir

C_DIR = Path(__file__).parent / "c"
DRIVER_SOURCES = ["fuzz_driver.c", "fuzz_pointers.c", "fuzz_pointers3.c"]
STATES_PER_RUN = 2_500  # five runs: 12,500 serialized states

# (model, FMI version, interface, pointer cases at least): the co-simulation FMU of a network with
# parameters, and a continuous-time model whose binary offers Model Exchange and co-simulation
RUNS = [("nonlinear", 2, "cs", 45), ("nonlinear", 3, "cs", 110), ("pendulum", 2, "me", 55),
        ("pendulum", 3, "me", 110), ("pendulum", 2, "cs", 45)]


MODELS.setdefault("pendulum", bounded_pendulum())  # as test_fmu_me_events registers it: one build per session


@pytest.fixture(scope="module")
def fuzz_driver(tmp_path_factory):
    """fmu -> the driver compiled against that FMU's sources (the layout of its state, its value references)."""
    folder, drivers = tmp_path_factory.mktemp("fuzz"), {}

    def compiled(fmu: Path) -> Path:
        if fmu not in drivers:
            drivers[fmu] = folder / f"fuzz_driver_{len(drivers)}"
            run_compiler(["-std=c99", "-O1", f"-I{fmi_header_dir()}", f"-I{unzipped(fmu) / 'sources'}",
                          *(str(C_DIR / name) for name in DRIVER_SOURCES), "-o", str(drivers[fmu]), "-ldl", "-lm"],
                         what="compiling the FMU fuzz driver")
        return drivers[fmu]

    return compiled


@pytest.mark.parametrize("model, version, interface, min_pointer_cases", RUNS,
                         ids=[f"{m}-fmi{v}-{i}" for m, v, i, _ in RUNS])
def test_hostile_states_and_null_pointers_never_crash_or_hang(fuzz_driver, model, version, interface,
                                                              min_pointer_cases):
    fmu = built_fmu(model, version)
    exe = fuzz_driver(fmu)
    binary = next((unzipped(fmu) / "binaries").rglob("*.so"))
    done = subprocess.run([str(exe), str(binary), str(version), interface, str(STATES_PER_RUN), "1"],
                          capture_output=True, text=True, timeout=300)
    report = [line for line in done.stdout.splitlines() if not line.startswith("pointer case ")]
    assert done.returncode == 0, "\n".join(report[-40:]) + done.stderr[-2000:]
    summary = report[-1].split()
    assert summary[:2] == ["states", str(STATES_PER_RUN)] and summary[-2:] == ["failures", "0"], report[-5:]
    assert int(summary[3]) >= min_pointer_cases, report[-1]  # the cases ran


@pytest.mark.parametrize("version", [2, 3])
def test_a_corrupted_state_is_refused_and_the_instance_keeps_its_own(version):
    """One flipped bit in the payload: refused by its checksum, with a message; the instance steps on."""
    model = MODELS["linear"]
    u = excitation(model, 10)
    inst = Instance(built_fmu("linear", version)).initialize()
    inst.run(model, u[:3])
    blob = bytearray(inst.serialize(inst.get_state()))
    blob[-9] ^= 0x10  # inside the model state x
    expected = inst.run(model, u[3:6])
    inst.reset()
    inst.initialize()
    inst.run(model, u[:3])
    with pytest.raises(FMICallException):
        inst.deserialize(bytes(blob))
    assert "checksum" in inst.errors()[-1] and "keeps its state" in inst.errors()[-1]
    np.testing.assert_array_equal(inst.run(model, u[3:6]), expected)  # not in the error state, state unchanged
    inst.close()
