"""The stepping rule (docs/fmu.md): time in whole samples, any step size h > 0, the max-samples limit.

A long run past t = 256 s and 10^7 samples, stepped from C, is in test_fmu_c_importer.py.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmu_cases import MODELS, FMICallException, Instance, built_fmu, excitation, get_model

VERSIONS = [2, 3]


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("start_time", [256.0, 1e6])
def test_gru_fmu_runs_in_fmpy_from_late_start_times(version, start_time):
    """fmpy's step sizes t[k+1] - t[k] carry a rounding error ~1e-16 t: the FMU used to stop at t = 256 s.
    (The inputs are constant start values: fmpy's own input tables misbehave at t = 1e6 s.)"""
    model = get_model("valve_gru")
    u, y0 = np.array([7.0, 3.0]), np.array([4e-4, 2.5e5])
    res = fmpy.simulate_fmu(str(built_fmu("valve_gru", version)), start_time=start_time,
                            stop_time=start_time + 1999 * 4e-5, output_interval=4e-5,
                            start_values={"s_start": y0[0], "p_start": y0[1], "u1": u[0], "u2": u[1]})
    got = np.column_stack([res["s"], res["p"]])
    assert len(got) > 1900  # fmpy itself stops within 1e-9 relative of the stop time
    want = model.simulate(np.tile(u, (len(got), 1)), y0)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
    assert np.ptp(want[:, 1]) > 10.0, "the outputs must move"


@pytest.mark.parametrize("version", VERSIONS)
def test_step_of_one_and_a_half_ts_matches_stepping_at_ts_at_the_sample_instants(version):
    model = MODELS["nonlinear"]
    Ts = model.spec.Ts
    u = np.repeat(excitation(model, 8), 3, axis=0)  # each input held for 3 samples = 2 steps of 1.5 Ts
    want = model.simulate(np.vstack([u, u[-1:]]), [0.1, 0.4])
    inst = Instance(built_fmu("nonlinear", version)).initialize({"s_start": 0.1, "q_start": 0.4})
    got = []
    for j in range(16):  # communication points at 1.5 j Ts
        inst.set({"u1": u[3 * (j // 2), 0], "u2": u[3 * (j // 2), 1]})
        assert inst.step(1.5 * Ts, t=1.5 * j * Ts) == 0
        got.append(inst.get(["s", "q"]))
    reached = [int(np.floor(1.5 * (j + 1) + 1e-9)) for j in range(16)]  # the last sample instant reached
    np.testing.assert_allclose(got, want[reached], rtol=1e-12, atol=1e-15)
    assert inst.fmu_time() == pytest.approx(24 * Ts, rel=1e-15)
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_steps_shorter_than_ts_sample_the_input_held_at_each_instant(version):
    """With h = Ts/4 the input changes at every communication point; each sample uses the one held at t_k,
    and a step that reaches no sample instant changes nothing."""
    model = MODELS["nonlinear"]
    Ts = model.spec.Ts
    fine = excitation(model, 41, seed=5)  # the input at t = i Ts/4
    want = model.simulate(fine[::4], [0.0, 1.0])  # sample k uses the input at t_k = 4k quarter steps
    inst = Instance(built_fmu("nonlinear", version)).initialize()
    outputs = []
    for i in range(40):
        inst.set({"u1": fine[i, 0], "u2": fine[i, 1]})
        inst.step(Ts / 4, t=i * Ts / 4)
        outputs.append(inst.get(["s", "q"]))
    outputs = np.array(outputs)
    np.testing.assert_allclose(outputs[3::4], want[1:], rtol=1e-12, atol=1e-15)  # at t = (k+1) Ts
    for q in (0, 1, 2):  # between sample instants the outputs stay at the last sample reached
        np.testing.assert_array_equal(outputs[q::4], np.vstack([want[:1], outputs[3:-4:4]]))
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_max_samples_per_step_is_a_parameter_and_a_longer_step_is_refused(version):
    inst = Instance(built_fmu("linear", version)).initialize()
    assert inst.step(0.01 * 10) == 0  # the default limit is 10 000 000 samples
    inst.set_int("max_samples_per_step", 4)  # tunable: set in step mode
    assert inst.step(0.04) == 0
    with pytest.raises(FMICallException):
        inst.step(0.05)
    assert "would take 5 samples of Ts = 0.01 s, more than the limit of 4 (parameter max_samples_per_step)" \
        in inst.errors()[-1]
    inst.close()


HUGE_STEP = textwrap.dedent("""
    import sys
    from pathlib import Path
    sys.path.insert(0, {tests!r})
    from fmu_cases import Instance, FMICallException
    for path in sys.argv[1:]:
        inst = Instance(Path(path)).initialize()
        try:
            inst.step(1e9)
        except FMICallException:
            print("refused", inst.errors()[-1])
        print("time after", inst.get(["time"])[0])
""")


def test_huge_step_is_refused_at_once(tmp_path):
    """doStep(0, 1e9 s) at Ts = 40 us would take 2.5e13 samples (weeks); it must return an error at once.
    Run in a subprocess with a timeout so that a regression fails instead of hanging the suite."""
    fmus = [str(built_fmu("valve_gru", v)) for v in VERSIONS]
    script = HUGE_STEP.format(tests=str(Path(__file__).parent))
    done = subprocess.run([sys.executable, "-c", script, *fmus], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 4, done.stdout
    for refused, after in zip(lines[0::2], lines[1::2]):
        assert "refused" in refused and "would take 25000000000000 samples of Ts = 4e-05 s" in refused
        assert "limit of 10000000 (parameter max_samples_per_step)" in refused
        assert after == "time after 0.0"  # nothing was computed


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("h", [0.0, -0.01, float("nan"), float("inf")])
def test_step_size_must_be_positive_and_finite(version, h):
    inst = Instance(built_fmu("linear", version)).initialize()
    with pytest.raises(FMICallException):
        inst.step(h)
    assert "the communication step size must be positive and finite" in inst.errors()[-1]
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_communication_point_off_the_fmu_time_is_an_error(version):
    inst = Instance(built_fmu("linear", version)).initialize()
    inst.step(0.015)
    with pytest.raises(FMICallException):
        inst.step(0.01, t=0.5)
    assert "currentCommunicationPoint must be where the previous step ended, t = 0.015" in inst.errors()[-1]
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_communication_points_accumulated_by_the_importer_are_accepted(version):
    """An importer that adds h to its time at every step drifts from k * Ts by rounding; the FMU follows it."""
    model = MODELS["linear"]
    u = excitation(model, 1001)
    inst = Instance(built_fmu("linear", version)).initialize(start_time=1e5)
    t, h = 1e5, 0.01
    for k in range(1000):
        inst.set({"force": u[k, 0]})
        inst.step(h, t=t)
        t += h
    np.testing.assert_allclose(inst.get(["pos", "vel"]), model.simulate(u, [0.1, 0.0])[-1], rtol=1e-12)
    inst.close()
