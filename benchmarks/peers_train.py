"""Train one peer (deepSI 0.4.4 or tsfast 0.5.0) for a CPU budget; the worker half of benchmarks/peers.py.

Runs in the peers' own virtual environment (see benchmarks/peers.py for how it is made), so
it imports neither nnfmu nor anything the peers do not install. It reads the arrays that
peers.py wrote (standardised with the training statistics), trains with the peer's own
training loop and defaults until the process has used ``--budget`` CPU-seconds, predicts
the test trajectories and writes::

    <out>.npz   pred: (n_test, n_steps, n_y) standardised predictions (NaN in the init window)
    <out>.json  trajectory_steps, cpu_s, wall_s, what was trained

One "trajectory-step" is one sample of one training sequence through the forward pass, the
backward pass and the update; validation, data loading and everything else the peer does
while training count in the CPU time but not as steps.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

HIDDEN = 32
INIT = 50  # measured samples every model may use to set its state before scoring (as peers.py)
# deepSI 0.4.4 has no recurrent network: "deepsi-fit-nnfmu-gru" is nnfmu's GRU with output feedback,
# written here in torch as a deepSI Custom_SUBNET and trained by deepSI.fit (deepSI's loop, not its model).
PEERS = ("deepsi-subnet", "deepsi-fit-nnfmu-gru", "tsfast-ar-gru", "tsfast-gru")


class BudgetSpent(Exception):
    """The CPU budget is used up."""


class Budget:
    """CPU-seconds of training: started where the training starts, after the data are prepared."""

    def __init__(self, seconds: float):
        self.seconds, self.cpu0, self.wall0 = seconds, None, None

    def start(self) -> None:
        self.cpu0, self.wall0 = time.process_time(), time.perf_counter()

    def spent(self) -> tuple[float, float]:
        return time.process_time() - self.cpu0, time.perf_counter() - self.wall0

    def check(self) -> None:
        if self.spent()[0] > self.seconds:
            raise BudgetSpent

    def interrupt_when_spent(self) -> None:
        """deepSI.fit stops cleanly (keeping its best model) on KeyboardInterrupt."""
        if self.spent()[0] > self.seconds:
            raise KeyboardInterrupt


# ---- deepSI -------------------------------------------------------------------------------------
def _deepsi_data(arrays, split: str):
    from nonlinear_benchmarks import Input_output_data

    return [Input_output_data(u=u, y=y, sampling_time=1.0) for u, y in zip(arrays[f"{split}_u"], arrays[f"{split}_y"])]


def _gru_feedback_model(n_u: int, n_y: int):
    """nnfmu's network written as a deepSI model: GRU on [y_k, u_k], y_{k+1} = y_k + 0.1 * readout(h)."""
    import deepSI

    class GRUFeedback(deepSI.Custom_SUBNET):
        def __init__(self):
            super().__init__()
            self.nu, self.ny, self.na, self.nb = n_u, n_y, 1, 1
            self.cell = torch.nn.GRUCell(n_u + n_y, HIDDEN)
            self.readout = torch.nn.Linear(HIDDEN, n_y)
            self.norm = type("Unit", (), {"ystd": torch.ones(n_y)})()  # data arrive standardised

        def forward(self, upast, ypast, ufuture, yfuture=None):
            y, h, out = ypast[:, -1], None, []
            inputs = torch.cat([upast[:, -1:], ufuture[:, :-1]], dim=1)
            for u in inputs.unbind(1):
                h = self.cell(torch.cat([y, u], dim=1), h)
                y = y + 0.1 * self.readout(h)
                out.append(y)
            return torch.stack(out, dim=1)

    return GRUFeedback()


def train_deepsi(arrays, model_name: str, budget: Budget) -> tuple[np.ndarray, int, dict]:
    """deepSI.fit with its defaults (T=50, batch 256, Adam, validation every 250 iterations)."""
    import deepSI

    train, valid = _deepsi_data(arrays, "train"), _deepsi_data(arrays, "valid")
    n_u, n_y = arrays["train_u"].shape[-1], arrays["train_y"].shape[-1]
    if model_name == "subnet":
        model = deepSI.SUBNET(n_u, n_y, deepSI.Norm(np.zeros(n_u), np.ones(n_u), np.zeros(n_y), np.ones(n_y)))
    else:
        model = _gru_feedback_model(n_u, n_y)
    T, batch, its = 50, 256, [0]

    def loss(model, *batch_arrays):
        budget.interrupt_when_spent()
        its[0] += 1
        return deepSI.fitting.compute_NMSE(model, *batch_arrays)

    budget.start()
    deepSI.fit(model, train, valid, n_its=10**9, T=T, batch_size=batch, loss_fun=loss)
    info = {"T": T, "batch_size": batch, "iterations": its[0], "cpu_s": budget.spent()[0],
            "wall_s": budget.spent()[1]}
    n_past = max(model.na, model.nb)
    preds = []
    with torch.no_grad():
        for u, y in zip(arrays["test_u"], arrays["test_y"]):
            past = slice(INIT - n_past, INIT)
            args = [torch.as_tensor(a[None], dtype=torch.float32) for a in (u[past], y[past], u[INIT:])]
            pred = np.full(y.shape, np.nan)
            pred[INIT:] = model(*args)[0].numpy()
            preds.append(pred)
    return np.stack(preds), its[0] * batch * T, info


# ---- tsfast -------------------------------------------------------------------------------------
def _hdf5_folders(arrays, root: Path) -> None:
    import h5py

    for split in ("train", "valid", "test"):
        (root / split).mkdir(parents=True)
        for i, (u, y) in enumerate(zip(arrays[f"{split}_u"], arrays[f"{split}_y"])):
            with h5py.File(root / split / f"{i:04d}.hdf5", "w") as f:
                for j in range(u.shape[1]):
                    f[f"u{j}"] = u[:, j].astype(np.float32)
                for j in range(y.shape[1]):
                    f[f"y{j}"] = y[:, j].astype(np.float32)


def train_tsfast(arrays, work: Path, budget: Budget) -> tuple[np.ndarray, int, dict]:
    """tsfast's RNNLearner (GRU, its simulation model) with its data-loader defaults: windows of 100, batch 64."""
    from tsfast.training import RNNLearner
    from tsfast.tsdata import create_dls

    _hdf5_folders(arrays, work)
    n_u, n_y = arrays["train_u"].shape[-1], arrays["train_y"].shape[-1]
    win, bs = 100, 64
    dls = create_dls(u=[f"u{j}" for j in range(n_u)], y=[f"y{j}" for j in range(n_y)], dataset=work,
                     win_sz=win, bs=bs)
    learner = RNNLearner(dls, rnn_type="gru", hidden_size=HIDDEN, num_layers=1, n_skip=INIT, show_bar=False,
                         device=torch.device("cpu"))
    epochs = _epochs_until_spent(learner, budget)
    info = {"learner": "RNNLearner", "win_sz": win, "bs": bs, "epochs": epochs, "cpu_s": budget.spent()[0],
            "wall_s": budget.spent()[1]}
    learner.model.eval()
    preds = []
    with torch.no_grad():
        for u, y in zip(arrays["test_u"], arrays["test_y"]):
            pred = learner.model(torch.as_tensor(u[None], dtype=torch.float32))[0].numpy().astype(float)
            pred[:INIT] = np.nan
            preds.append(pred)
    return np.stack(preds), epochs * len(dls.train) * bs * win, info


def train_tsfast_ar(arrays, work: Path, budget: Budget) -> tuple[np.ndarray, int, dict]:
    """tsfast's output-feedback learner, ``AR_RNNLearner`` (GRU-32): windows of 100, batch 64 (its defaults).

    It trains one step ahead with the measured outputs fed back (teacher forcing), here with
    ``prediction_concat(t_offset=1)``: the input at step k is (u_k, y_{k-1}). AR_RNNLearner's own
    default, ``t_offset=0``, gives the network y_k among the inputs that predict y_k (its free run
    diverged: NRMSE 3.10 after one epoch in a trial run). The test free run uses tsfast's
    ``AR_Model`` in autoregressive mode on the trained network, its hidden state carried from step
    to step: teacher-forced through the first INIT samples, then fed its own predictions.
    """
    from tsfast.models._core.layers import AR_Model
    from tsfast.training import AR_RNNLearner
    from tsfast.training.transforms import prediction_concat
    from tsfast.tsdata import create_dls

    _hdf5_folders(arrays, work)
    n_u, n_y = arrays["train_u"].shape[-1], arrays["train_y"].shape[-1]
    win, bs = 100, 64
    dls = create_dls(u=[f"u{j}" for j in range(n_u)], y=[f"y{j}" for j in range(n_y)], dataset=work,
                     win_sz=win, bs=bs)
    learner = AR_RNNLearner(dls, rnn_type="gru", hidden_size=HIDDEN, num_layers=1, n_skip=INIT, show_bar=False,
                            device=torch.device("cpu"), transforms=[prediction_concat(t_offset=1)])
    epochs = _epochs_until_spent(learner, budget)
    info = {"learner": "AR_RNNLearner", "win_sz": win, "bs": bs, "epochs": epochs, "cpu_s": budget.spent()[0],
            "wall_s": budget.spent()[1]}
    scaled = learner.model.eval()  # ScaledModel(AR_Model(SimpleRNN)): normalises [u, y], denormalises y
    net = scaled.model.model
    net.return_state = True
    free_run = AR_Model(net, ar=True, model_has_state=True, return_state=True, out_sz=n_y)
    preds = []
    with torch.no_grad():
        for u, y in zip(arrays["test_u"], arrays["test_y"]):
            uy = np.concatenate([u[1:INIT], y[:INIT - 1]], 1)  # (u_k, y_{k-1}), k < INIT: as in training
            uy = scaled.input_norm.normalize(torch.as_tensor(uy[None], dtype=torch.float32))
            _, state = free_run(uy, ar=False)
            y_last = torch.as_tensor(np.concatenate([u[INIT - 1], y[INIT - 1]])[None, None], dtype=torch.float32)
            state = {"h": state["h"], "y_init": scaled.input_norm.normalize(y_last)[:, :, n_u:]}
            un = scaled.input_norm.normalize(torch.as_tensor(np.concatenate([u, y], 1)[None], dtype=torch.float32))
            out, _ = free_run(un[:, INIT:, :n_u], state=state, ar=True)
            pred = np.full(y.shape, np.nan)
            pred[INIT:] = scaled.output_norm.denormalize(out)[0].numpy()
            preds.append(pred)
    return np.stack(preds), epochs * len(dls.train) * bs * (win - 1), info  # t_offset=1: windows of win - 1


def _epochs_until_spent(learner, budget: Budget) -> int:
    """What Learner.fit does, epoch by epoch, until the budget is spent; returns the epochs run."""
    budget.start()
    learner.setup()
    epochs = 0
    while True:
        learner.train_one_epoch(epoch=epochs, n_epoch=epochs + 1)
        learner.validate()
        epochs += 1
        try:
            budget.check()
        except BudgetSpent:
            return epochs


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("peer", choices=PEERS)
    p.add_argument("--arrays", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--budget", type=float, required=True, help="CPU-seconds of training")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    arrays = dict(np.load(args.arrays))
    out = Path(args.out)
    budget = Budget(args.budget)
    if args.peer.startswith("deepsi-"):
        pred, steps, info = train_deepsi(arrays, "subnet" if args.peer == "deepsi-subnet" else "nnfmu-gru", budget)
    elif args.peer == "tsfast-ar-gru":
        pred, steps, info = train_tsfast_ar(arrays, out.with_suffix(".hdf5-data"), budget)
    else:
        pred, steps, info = train_tsfast(arrays, out.with_suffix(".hdf5-data"), budget)
    np.savez(out.with_suffix(".npz"), pred=pred)
    out.with_suffix(".json").write_text(json.dumps({"trajectory_steps": steps, **info}))


if __name__ == "__main__":
    main()
