"""The hybrid's GPU paths, as far as a machine without a GPU can check them: when they apply, what they cache,
and that a failure falls back to the eager path with one warning and the same numbers.

On a GPU, the translated physics runs through torch.compile (:mod:`nnfmu.hybrid.casadi_torch`) and the
training free run is recorded as CUDA graphs (:mod:`nnfmu.hybrid.graphed`). Their values and gradients
against the eager path are measured on a GPU by benchmarks/hybrid_speed.py (docs/scaling.md). Here the
compiler and the recorder are replaced by stand-ins that either run the code as given or fail, so the
bookkeeping around them (device choice, caches, fallbacks, the trainer's hook) is what is tested.
"""

from __future__ import annotations

import copy
import dataclasses
import warnings

import pytest
import torch

from nnfmu.hybrid import HybridConfig, casadi_torch, graphed, physics_system, sx_to_torch
from nnfmu.models import architectures, build_model
from nnfmu.training.compiled_rollout import ENV_SWITCH, training_rollout


def _valve_ode_inputs(batch: int = 5) -> tuple[torch.Tensor, ...]:
    system = physics_system("valve")
    x = torch.tensor([[6e-5, 0.0, 6e-5, 0.0, 3e5, 5e-4, 0.0]], dtype=torch.float64).repeat(batch, 1)
    x[:, 4] += torch.linspace(0.0, 1e5, batch, dtype=torch.float64)
    u = torch.full((batch, 2), 120.0, dtype=torch.float64)
    return x, u, torch.tensor(system.parameter_values(), dtype=torch.float64)


@pytest.fixture
def fuse_on_cpu(monkeypatch):
    """Treat the CPU as a device whose translated code is fused, with torch.compile replaced by ``compiler``."""
    calls = []

    def install(compiler):
        def compile_(fn, **kwargs):
            calls.append(kwargs)
            return compiler(fn)
        monkeypatch.setattr(casadi_torch, "FUSED_DEVICES", ("cpu",))
        monkeypatch.setattr(torch, "compile", compile_)
        return calls
    return install


def test_fused_code_is_what_evaluates_compiled_once_for_every_batch_size(fuse_on_cpu, monkeypatch):
    ran = []

    def counting(fn):
        def run(*args):
            ran.append(1)
            return fn(*args)
        return run
    calls = fuse_on_cpu(counting)
    ode = sx_to_torch(physics_system("valve").ode)
    fused = [ode.evaluate(_valve_ode_inputs(5)), ode(*_valve_ode_inputs(2))]  # the stand-in runs the code as given
    assert len(calls) == 1 and calls[0] == {"fullgraph": True, "dynamic": True} and len(ran) == 2
    monkeypatch.setattr(casadi_torch, "FUSED_DEVICES", ())
    for out, batch in zip(fused, (5, 2)):
        torch.testing.assert_close(out[0], ode.evaluate(_valve_ode_inputs(batch))[0], rtol=0, atol=0)


def test_a_failing_compiler_warns_once_and_the_numbers_stay(fuse_on_cpu, monkeypatch):
    def broken(fn):
        def run(*args):
            raise RuntimeError("no Triton here\nsecond line")
        return run
    fuse_on_cpu(broken)
    ode = sx_to_torch(physics_system("valve").ode)
    with pytest.warns(RuntimeWarning, match="cannot fuse.*no Triton here.*one by one"):
        first = ode.evaluate(_valve_ode_inputs())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        second = ode.evaluate(_valve_ode_inputs())  # no second warning: it stays eager
    monkeypatch.setattr(casadi_torch, "FUSED_DEVICES", ())
    reference = ode.evaluate(_valve_ode_inputs())
    for out in (first, second):
        torch.testing.assert_close(out[0], reference[0], rtol=0, atol=0)


def test_fusing_is_off_with_the_switch_and_for_autograd_gradients(fuse_on_cpu, monkeypatch):
    calls = fuse_on_cpu(lambda fn: fn)
    sx_to_torch(physics_system("valve").ode, gradients="autograd").evaluate(_valve_ode_inputs())
    monkeypatch.setenv(ENV_SWITCH, "0")
    sx_to_torch(physics_system("valve").ode).evaluate(_valve_ode_inputs())
    assert calls == []


# ---- the CUDA graphs of the training free run ----------------------------------------------------

def _hybrid():
    model = build_model(HybridConfig(n_u=2, n_y=2, physics="valve", hidden=8, physics_backend="sx")).double()
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in model.correction.parameters():
            p.copy_(0.1 * torch.randn(p.shape, generator=g, dtype=torch.float64))
    u = 100.0 + 20.0 * torch.rand(3, 4, 2, generator=g, dtype=torch.float64)
    y = torch.tensor([5e-4, 3e5], dtype=torch.float64).repeat(3, 4, 1)
    return model.train(), model.normalise_u(u), model.normalise_y(y)


@pytest.fixture
def record_on_cpu(monkeypatch):
    """Let graphs apply on the CPU, with make_graphed_callables replaced: the module runs as given."""
    recorded = []

    def make_graphed_callables(module, sample_args, **kwargs):
        recorded.append(tuple(a.shape for a in sample_args))
        return module
    monkeypatch.setattr(torch.cuda, "make_graphed_callables", make_graphed_callables)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(graphed, "_on_gpu", lambda model: True)
    return recorded


def test_graphs_apply_only_on_a_gpu_in_training():
    model, _, _ = _hybrid()
    assert graphed.graphed_rollout(model) is None  # on the CPU: the trainer's other paths
    assert graphed.graphed_rollout(model.eval()) is None


def test_the_trainer_takes_the_recorded_free_run_and_its_numbers(record_on_cpu):
    model, un, yn = _hybrid()
    free_run = training_rollout(model)
    out = free_run(un, yn)
    out.square().mean().backward()
    grads = [p.grad.clone() for p in model.correction.parameters()]
    model.zero_grad()
    eager = model.rollout_normalised(un, yn[:, 0])
    eager.square().mean().backward()
    torch.testing.assert_close(out, eager, rtol=0, atol=0)
    for g, p in zip(grads, model.correction.parameters()):
        torch.testing.assert_close(g, p.grad, rtol=0, atol=0)
    assert record_on_cpu == [((3, 4, 2), (3, 2))]


def test_one_recording_per_batch_shape_and_again_when_the_weights_move(record_on_cpu, monkeypatch):
    monkeypatch.setattr(graphed, "MAX_GRAPHS", 2)
    model, un, yn = _hybrid()
    free_run = graphed.graphed_rollout(model)
    free_run(un, yn)
    free_run(un, yn)  # the same shape: replayed
    free_run(un[:2], yn[:2])  # the last, smaller batch of an epoch
    assert len(record_on_cpu) == 2
    model.double()  # a no-op cast keeps the storage
    free_run(un, yn)
    assert len(record_on_cpu) == 2
    for p in model.parameters():
        p.data = p.data.clone()  # storage moved (as .to(device) does): record again
    free_run(un, yn)
    assert len(record_on_cpu) == 3 and len(model._cuda_graphs.graphs) == 2  # the oldest was dropped


def test_validation_and_init_windows_run_eagerly(record_on_cpu):
    model, un, yn = _hybrid()
    free_run = graphed.graphed_rollout(model)
    with torch.no_grad():
        free_run(un, yn)
    assert record_on_cpu == []


def test_a_failed_recording_warns_once_and_trains_eagerly(record_on_cpu, monkeypatch):
    def refuse(module, sample_args, **kwargs):
        raise RuntimeError("operation not permitted when stream is capturing")
    monkeypatch.setattr(torch.cuda, "make_graphed_callables", refuse)
    model, un, yn = _hybrid()
    with pytest.warns(RuntimeWarning, match="cannot be recorded as a CUDA graph.*trains eagerly"):
        out = graphed.graphed_rollout(model)(un, yn)
    torch.testing.assert_close(out, model.rollout_normalised(un, yn[:, 0]), rtol=0, atol=0)
    assert graphed.graphed_rollout(model) is None  # from then on the plain path


def test_a_copy_of_the_model_starts_without_graphs(record_on_cpu):
    model, un, yn = _hybrid()
    graphed.graphed_rollout(model)(un, yn)
    assert len(copy.deepcopy(model)._cuda_graphs.graphs) == 0


def test_the_trainer_asks_the_architecture_record_for_its_training_rollout(record_on_cpu, monkeypatch):
    """Where graphs would apply, a record without the hook (dataclasses.replace) trains by the plain path."""
    model, un, yn = _hybrid()
    record = architectures.architecture("hybrid")
    monkeypatch.setitem(architectures._RECORDS, "hybrid", dataclasses.replace(record, training_rollout=None))
    out = training_rollout(model)(un, yn)
    torch.testing.assert_close(out, model.rollout_normalised(un, yn[:, 0]), rtol=0, atol=0)
    assert record_on_cpu == []  # nothing recorded: the graphs come from the record, not from the trainer
