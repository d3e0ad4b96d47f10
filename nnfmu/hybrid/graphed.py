"""A hybrid's training free run on a CUDA device as one CUDA graph forward and one backward.

With the ``sx`` physics backend a hybrid step is a few hundred small torch operations (the
translated ODE and its CasADi reverse mode in every RK4 stage, and the correction network).
On a GPU each costs a kernel launch and the Python, dispatcher and autograd work around it,
microseconds apiece, while the arithmetic on a batch of a few dozen trajectories takes far
less: a valve epoch took longer on an H100 than on two CPU cores (issue 23). This module
records the whole free run of a training batch, forward and backward, as two CUDA graphs
(:func:`torch.cuda.make_graphed_callables`) and replays them: per batch, one graph launch
forward and one backward instead of tens of thousands of launches.

``graphed_rollout(model)`` is the hybrid's ``training_rollout`` hook
(:attr:`nnfmu.models.architectures.Architecture.training_rollout`): the trainer calls what it returns
once per batch, then back-propagates once, which is the pattern the graphs need (a second forward
before the backward would overwrite the first's saved values). Validation and export run the
ordinary eager free run.

It applies to a hybrid on a CUDA device in training mode, without an init window. Graphs are
recorded per batch shape (the last batch of an epoch may be smaller) and again when the parameters'
storage moves (``.to()``), at most :data:`MAX_GRAPHS` kept; recording costs about two eager
batches, once. If recording fails (an operation that cannot be captured, e.g. a host
synchronisation in a user's physics), the model warns once and trains eagerly: same numbers, slower.
``NNFMU_COMPILED_ROLLOUT=0`` turns the graphs off, as it does the CPU's compiled paths.
"""

from __future__ import annotations

import os
import warnings

import torch
from torch import nn

from nnfmu.training.compiled_rollout import ENV_SWITCH

MAX_GRAPHS = 4  #: recorded batch shapes kept per model (each holds its activations' memory)
WARMUP = 1  #: eager iterations on a side stream before recording (make_graphed_callables' warm-up)


class _FreeRun(nn.Module):
    """``forward(un, yn0)``: the model's eager free run, as a module whose parameters are the model's."""

    def __init__(self, model: nn.Module):
        super().__init__()
        self.model = model

    def forward(self, un: torch.Tensor, yn0: torch.Tensor) -> torch.Tensor:
        return self.model._free_run_eager(un, yn0)


class RecordedFreeRuns:
    """The recorded free runs of one model, by (batch shape, dtype, parameter storage).

    Kept on the model (``model._cuda_graphs``); a copy of the model starts without graphs.
    """

    def __init__(self):
        self.graphs: dict[tuple, nn.Module] = {}
        self.failed = False

    def __deepcopy__(self, memo) -> "RecordedFreeRuns":
        return RecordedFreeRuns()

    def __getstate__(self) -> dict:
        return {"graphs": {}, "failed": False}

    def run(self, model: nn.Module, un: torch.Tensor, yn0: torch.Tensor) -> torch.Tensor:
        """``model``'s free run (B, T, n_y) from ``un`` (B, T, n_u) and ``yn0`` (B, n_y), by a recorded graph."""
        key = (tuple(un.shape), tuple(yn0.shape), un.dtype, yn0.dtype,
               tuple((p.data_ptr(), p.requires_grad) for p in model.parameters()))
        graph = self.graphs.get(key)
        if graph is None:
            graph = self._record(model, un, yn0)
            if graph is None:
                return model._free_run_eager(un, yn0)
            if len(self.graphs) >= MAX_GRAPHS:
                self.graphs.pop(next(iter(self.graphs)))
            self.graphs[key] = graph
        return graph(un, yn0)

    def _record(self, model: nn.Module, un: torch.Tensor, yn0: torch.Tensor) -> nn.Module | None:
        module = _FreeRun(model).train(model.training)
        try:
            with warnings.catch_warnings():
                # The warm-up runs on a side stream while the last batch's autograd graph may still be alive:
                # torch warns of a stream mismatch that costs one synchronisation here, none in the replays.
                warnings.filterwarnings("ignore", message="The AccumulateGrad node's stream does not match")
                return torch.cuda.make_graphed_callables(module, (un.detach().clone(), yn0.detach().clone()),
                                                         num_warmup_iters=WARMUP, allow_unused_input=True)
        except (RuntimeError, AssertionError, TypeError) as exc:
            self.failed = True
            warnings.warn(f"the hybrid's free run cannot be recorded as a CUDA graph ({str(exc).splitlines()[0]}); "
                          "it trains eagerly (same numbers, slower)", RuntimeWarning, stacklevel=4)
            return None


def applies(model) -> bool:
    """Whether the training free run of ``model`` (a HybridStepModel) runs as CUDA graphs."""
    if os.environ.get(ENV_SWITCH, "1") == "0" or not model.training or model.config.init_window > 1:
        return False
    state = getattr(model, "_cuda_graphs", None)
    if state is not None and state.failed:
        return False
    return _on_gpu(model)


def _on_gpu(model) -> bool:
    return model.u_mean.device.type == "cuda" and torch.cuda.is_available()


def graphed_rollout(model):
    """``free_run(un, yn, past=None) -> (B, T, n_y)`` by replayed CUDA graphs, or None where they do not apply.

    ``un`` (B, T, n_u) and ``yn`` (B, T, n_y) are a training batch in normalised units; the free run starts
    from ``yn[:, 0]``, as :meth:`~nnfmu.models.StepModel.rollout_normalised` does. Call the result once per
    batch and back-propagate before the next call.
    """
    if not applies(model):
        return None
    graphs = getattr(model, "_cuda_graphs", None)
    if graphs is None:
        graphs = model._cuda_graphs = RecordedFreeRuns()

    def free_run(un: torch.Tensor, yn: torch.Tensor, past=None) -> torch.Tensor:
        if past is not None or not torch.is_grad_enabled():
            return model.rollout_normalised(un, yn[:, 0], None, past)
        out = graphs.run(model, un, yn[:, 0])
        model._check_finite(out)
        return out

    return free_run
