"""The default training's FMU (networks on a linear path, an ensemble of them) steps in one vectorised C function.

Issue 36: the network of a linear-path member and the members of an ensemble were separate CasADi Functions, so the
generated C called them from the step; only the step itself was cloned for AVX2/AVX-512 (``NNFMU_CLONES``), and the
networks ran in portable SSE2 code, 6x (one member) and 12x (two members) slower than the same network alone.
"""

from __future__ import annotations

import re
import zipfile

import pytest
import torch

from nnfmu.cosim import FmuSimulator
from nnfmu.export import build_fmu, casadi_model
from nnfmu.export.codegen import MODEL_BODY
from nnfmu.export.fmu import BuildOptions
from nnfmu.models import EnsembleStepModel
from tests.test_ensemble_mixed import corrected
from tests.test_linear_path import data, linear, rel  # noqa: F401 (fixtures)

pytestmark = pytest.mark.usefixtures("one_thread")



@pytest.mark.parametrize("kind", ["member", "ensemble", "mixed"])
def test_the_default_fmu_steps_in_one_function_and_equals_torch_and_the_exact_build(kind, data, linear,  # noqa: F811
                                                                                     tmp_path):
    gru = [corrected("gru", data, linear, [0.3, -0.2]), corrected("gru", data, linear, [-0.1, 0.2], g=-0.03)]
    with torch.no_grad():
        gru[1].net.readout.weight.mul_(-0.5)  # two members that differ
    model = {"member": gru[0], "ensemble": EnsembleStepModel.from_members(gru),
             "mixed": EnsembleStepModel.from_members([gru[0], corrected("lstm", data, linear, [0.1, 0.1])])}[kind]
    cmodel = casadi_model(model, name=kind)
    u, y = data.test.u[0], data.test.y[0]
    want = model.simulate(u, y[0])
    got = {}
    for build, options in {"exact": BuildOptions(profile="exact"), "fast": BuildOptions()}.items():
        fmu = build_fmu(cmodel, tmp_path / f"{build}.fmu", options=options)
        with zipfile.ZipFile(fmu) as z:
            source = z.read("sources/model_casadi.c").decode()
        (step,) = re.findall(r"^NNFMU_CLONES\nstatic int (casadi_f\d+)\(", source, re.M)  # the one cloned function
        body = dict(MODEL_BODY.findall(source))[step]
        assert not re.search(r"\bcasadi_f\d+\(", body), f"the step {step} calls another model function"
        with FmuSimulator(fmu, data.input_names, data.output_names, data.Ts) as sim:
            got[build] = sim.simulate(u, y[0])
        assert rel(got[build], want) < 1e-9
    assert rel(got["fast"], got["exact"]) < 1e-12



def test_nnfmu_info_gives_the_step_cost_of_an_fmu_and_of_its_checkpoint(data, linear, tmp_path):  # noqa: F811
    from nnfmu.cli.info import describe, render
    from nnfmu.models import save_checkpoint

    members = [corrected("gru", data, linear, [0.3, -0.2]), corrected("gru", data, linear, [-0.1, 0.2])]
    model = EnsembleStepModel.from_members(members)
    h, n_y, n_u, n_z = 8, data.n_y, data.n_u, linear.n_x
    # per member: the GRU's three gates and readout; the path's A z, B u, G n and C z
    weights = 2 * (3 * h * (h + n_y + n_u) + n_y * h + n_z * (n_z + n_u + n_y) + n_y * n_z)
    want = {"weights": weights, "weight_bytes": 8 * weights, "flops": 2 * weights, "precision": "float64"}
    save_checkpoint(tmp_path / "m.pt", model)
    assert describe(tmp_path / "m.pt")["step_cost"] == want
    for options, real in ((BuildOptions(profile="exact"), 8), (BuildOptions(), 8),
                          (BuildOptions(precision="float32"), 4)):
        fmu = build_fmu(casadi_model(model), tmp_path / "m.fmu", options=options)
        assert describe(fmu)["step_cost"] == dict(want, weight_bytes=real * weights,
                                                  precision="float32" if real == 4 else "float64")
    assert f"step cost: {weights} weights read per step" in render(describe(fmu))


def test_every_function_the_step_calls_is_cloned_with_it(tmp_path):
    """A hybrid's network is a Function called in every RK4 stage: it must run in the step's instruction set."""
    from nnfmu.export.codegen import STEP_ENTRY, called_from
    from nnfmu.hybrid import HybridConfig
    from nnfmu.models import build_model

    torch.manual_seed(0)
    hybrid = build_model(HybridConfig(n_u=2, n_y=2, physics="valve", hidden=8)).double().eval()
    with torch.no_grad():
        for prm in hybrid.correction.parameters():
            prm.normal_(0, 0.1)
    fmu = build_fmu(casadi_model(hybrid), tmp_path / "h.fmu")
    with zipfile.ZipFile(fmu) as z:
        source = z.read("sources/model_casadi.c").decode()
    stepped = called_from(source, STEP_ENTRY.search(source).group(1))
    assert len(stepped) >= 3  # the step, the network, the physics
    assert set(re.findall(r"^NNFMU_CLONES\nstatic int (casadi_f\d+)\(", source, re.M)) == stepped
