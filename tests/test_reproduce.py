"""``nnfmu reproduce``: the smoke study end to end, its results files, and resuming (skip, redo, continue)."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest
import torch

from nnfmu.cli import main
from nnfmu.errors import ConfigError, DataError
from nnfmu.models import load_checkpoint
from nnfmu.study import BUDGETS, Hyper, get_budget, reproduce
from nnfmu.study.tune import check_grid
from nnfmu.training import STRATEGIES
from builtin_networks import ARCHS

N_CELLS = 1 + 2 * 10 + 3 + 12 + 1  # data, train+export x 10, linear (2) + physics, 12 scores, report


@pytest.fixture
def study_copy(smoke_study, tmp_path):
    """A private copy of the smoke study to damage; the session's stays intact."""
    out = tmp_path / "study"
    shutil.copytree(smoke_study[0], out)
    return out


def _table_i(md: str) -> dict[str, tuple[str, str]]:
    """The rows of results.md's first table: label -> (series-parallel text, parallel text)."""
    block = md.split("| Network | Series-Parallel | Parallel |")[1].split("\n\n")[0]
    rows = [line.strip("|").split("|") for line in block.strip().splitlines()[1:]]
    return {r[0].strip(): (r[1].strip(), r[2].strip()) for r in rows}


def _cell(text: str) -> tuple[float, bool, bool]:
    """A Table I cell such as ``**0.480***`` -> (value, bold, starred)."""
    m = re.fullmatch(r"(\*\*)?([0-9.]+)(\*\*)?(\*)?( \([0-9.]+, [0-9.]+–[0-9.]+\))?", text)
    assert m and bool(m[1]) == bool(m[3]), text
    return float(m[2]), bool(m[1]), bool(m[4])


def test_smoke_study_scores_every_cell(smoke_study):
    out, result, _ = smoke_study
    doc = json.loads((out / "results.json").read_text())
    assert {(n["arch"], n["strategy"]) for n in doc["networks"]} == {(a, s) for a in ARCHS for s in STRATEGIES}
    assert [b["name"] for b in doc["baselines"]] == ["linear", "physics"]
    for row in doc["networks"] + doc["baselines"]:
        assert row["error"] is None, row["label"]
        assert np.isfinite(row["nrmse"]) and row["nrmse"] > 0
        assert set(row["per_output"]) == {"s", "p"}
        assert (out / row["paths"]["fmus"]).is_file()
    assert result.results == doc
    # the generating physics model is far better than any tiny 2-epoch network, up to the measurement noise
    from nnfmu.study import VALVE_NOISE

    physics = doc["baselines"][1]["nrmse"]
    assert physics < 0.03 + 2 * VALVE_NOISE and physics < min(n["nrmse"] for n in doc["networks"])
    assert all((out / f).is_file() and (out / f).stat().st_size > 10_000 for f in doc["figures"])


def test_generated_valve_data_carry_the_documented_measurement_noise(smoke_study, valve_small):
    from nnfmu.data import load_dataset
    from nnfmu.study.budgets import VALVE_NOISE

    data = load_dataset(smoke_study[0] / "data")
    assert data.source["measurement_noise"]["fraction_of_train_std"] == VALVE_NOISE > 0
    noise = np.concatenate(data.test.y) - np.concatenate(valve_small.test.y)  # same seed: same clean data
    ratio = noise.std(axis=0) / (VALVE_NOISE * valve_small.norm_stats("train").y_std)
    assert np.allclose(ratio, 1.0, atol=0.05) and np.abs(noise.mean(axis=0) / noise.std(axis=0)).max() < 0.05


def test_fmu_scores_equal_the_torch_free_run(smoke_study):
    """The table's numbers (FMUs in fmpy) reproduce each network's float64 torch test score."""
    doc = json.loads((smoke_study[0] / "results.json").read_text())
    for n in doc["networks"]:
        assert n["nrmse"] == pytest.approx(n["training"]["torch_test_nrmse"], rel=1e-7), n["label"]


def test_results_md_is_laid_out_like_table_i(smoke_study):
    out = smoke_study[0]
    doc = json.loads((out / "results.json").read_text())
    rows = _table_i((out / "results.md").read_text())
    assert list(rows)[:5] == [a.upper() for a in ARCHS]
    assert any(k.startswith("Linear state-space baseline") for k in rows)
    assert any(k.startswith("Physics model") for k in rows)
    for col, strategy in enumerate(("series-parallel", "parallel")):
        cells = {arch: _cell(rows[arch.upper()][col]) for arch in ARCHS}
        starred = [arch for arch in ARCHS if cells[arch][2]]
        assert starred == [min(ARCHS, key=lambda a: cells[a][0])]
        assert doc["best"][strategy] == f"{starred[0]}-{strategy}"
    for arch in ARCHS:
        (sp, sp_bold, _), (p, p_bold, _) = (_cell(t) for t in rows[arch.upper()])
        assert (sp_bold, p_bold) == ((True, False) if sp < p else (False, True))
    linear = next(v for k, v in rows.items() if k.startswith("Linear"))
    assert linear[0] == "—" and float(linear[1]) == pytest.approx(doc["baselines"][0]["nrmse"], abs=5e-4)


def test_second_run_skips_every_cell(smoke_study, study_copy):
    lines: list[str] = []
    again = reproduce("valve", study_copy, budget="smoke", progress=False, echo=lines.append)
    assert again.log.ran == []
    assert len(again.log.skipped) == N_CELLS == len(smoke_study[1].log.ran)
    assert all("done before, skipped" in line for line in lines)


def test_a_deleted_fmu_is_rebuilt_and_rescored_alone(smoke_study, study_copy):
    before = json.loads((study_copy / "results.json").read_text())
    (study_copy / "fmus" / "gru-parallel.fmu").unlink()
    again = reproduce("valve", study_copy, budget="smoke", progress=False, echo=None)
    assert again.log.ran == ["export gru parallel", "score gru-parallel",
                             "write results.md, results.json and figures"]
    after = {n["name"]: n["nrmse"] for n in again.results["networks"]}
    assert after == {n["name"]: n["nrmse"] for n in before["networks"]}


def test_an_interrupted_training_resumes_to_the_same_weights(smoke_study, study_copy):
    ckpt = study_copy / "models" / "gru-parallel.pt"
    finished = load_checkpoint(ckpt)
    ckpt.unlink()

    def interrupt(name, epoch, metrics):
        if name == "gru-parallel" and epoch == 1:
            raise KeyboardInterrupt  # as Ctrl-C between two epochs

    with pytest.raises(KeyboardInterrupt):
        reproduce("valve", study_copy, budget="smoke", progress=False, echo=None, callback=interrupt)
    partial = load_checkpoint(ckpt)
    assert partial["resume"]["epoch"] == 1 and "stop_reason" not in partial["summary"]

    lines: list[str] = []
    again = reproduce("valve", study_copy, budget="smoke", progress=False, echo=lines.append)
    assert again.log.ran[:3] == ["train gru parallel", "export gru parallel", "score gru-parallel"]
    assert any(line.startswith("[") and "train gru parallel: resumed" in line for line in lines)
    resumed = load_checkpoint(ckpt)
    assert resumed["summary"]["stop_reason"] == "epochs"
    for key, value in finished["state_dict"].items():
        assert torch.equal(value, resumed["state_dict"][key]), key


def test_a_cell_is_redone_when_an_output_is_missing_or_older_than_an_input(tmp_path):
    import os

    from nnfmu.study import Cell, run_cells

    src, out = tmp_path / "in.txt", tmp_path / "out.txt"
    src.write_text("1")
    runs = []
    cell = Cell("copy", (out,), (src,), lambda: runs.append(out.write_text(src.read_text())) or "copied")
    assert run_cells([cell], echo=None).ran == ["copy"]
    assert run_cells([cell], echo=None).skipped == ["copy"]
    os.utime(src, (out.stat().st_mtime + 10,) * 2)  # the input changed after the output was written
    assert run_cells([cell], echo=None).ran == ["copy"]
    out.unlink()
    assert run_cells([cell], echo=None).ran == ["copy"] and len(runs) == 3


def test_the_folder_refuses_a_study_with_other_settings(study_copy):
    with pytest.raises(ConfigError, match="other settings .*budget.*new --out"):
        reproduce("valve", study_copy, budget="quick", progress=False, echo=None)


def test_cli_resumes_and_prints_the_table(study_copy, capsys):
    assert main(["reproduce", "valve", "--out", str(study_copy), "--budget", "smoke", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "| Network | Series-Parallel | Parallel |" in printed
    assert f"ran 0 cells, skipped {N_CELLS} done before" in printed


def test_robot_study_needs_data(tmp_path):
    with pytest.raises(ConfigError, match="robot study needs measured data: pass --data"):
        reproduce("robot", tmp_path / "r", budget="smoke", progress=False, echo=None)


def test_data_without_a_test_split_is_refused(valve_small_dir, tmp_path):
    data = tmp_path / "no-test"
    shutil.copytree(valve_small_dir, data)
    (data / "test.npz").unlink()
    with pytest.raises(DataError, match="no 'test' split.*add test.npz"):
        reproduce("valve", tmp_path / "s", budget="smoke", data=data, progress=False, echo=None)


def test_robot_study_from_a_benchmark_mat_file(tmp_path):
    """The robot path on a small file in the re-cut benchmark layout (generated arm data)."""
    from scipy.io import savemat

    from nnfmu.physics import generate_dataset

    arm = generate_dataset("arm", size="small", seed=1)
    u = np.concatenate(arm.train.u)
    y = np.concatenate(arm.train.y)
    mat = tmp_path / "robot.mat"
    savemat(mat, {"u_train": u[:484].T, "y_train": y[:484].T, "u_test": arm.test.u[0].T, "y_test": arm.test.y[0].T})
    budget = get_budget("robot", "smoke").replace(archs=("gru",))
    result = reproduce("robot", tmp_path / "robot", budget=budget, data=mat, progress=False, echo=None)
    doc = result.results
    assert doc["dataset"]["outputs"] == [f"q{j}" for j in range(1, 7)]
    assert doc["dataset"]["splits"]["test"]["n_traj"] == 1
    assert all(np.isfinite(r["nrmse"]) for r in doc["networks"] + doc["baselines"])
    assert doc["baselines"][1]["label"].startswith("Arm physics model (nominal parameters, open loop")
    assert "Industrial robot (measured data)" in (result.results_md).read_text()


@pytest.mark.parametrize("system", sorted(BUDGETS))
def test_every_budget_builds_valid_configs(system):
    n_u, n_y = (2, 2) if system == "valve" else (6, 6)
    for budget in BUDGETS[system].values():
        for arch in budget.archs:
            hyper = budget.hyper[arch]
            assert hyper.model_config(arch, n_u, n_y).arch == arch
            for strategy in budget.strategies:
                cfg = hyper.train_config(strategy=strategy, epochs=budget.epochs, patience=budget.patience,
                                         seed=0, max_minutes=budget.max_minutes)
                assert cfg.epochs == budget.epochs
            check_grid(arch, hyper, budget.grid(arch), n_u, n_y)


def test_budget_lookup_and_options_errors():
    with pytest.raises(ConfigError, match="unknown budget 'fast'.*smoke, quick, paper"):
        get_budget("valve", "fast")
    with pytest.raises(ConfigError, match="unknown system 'pump'"):
        get_budget("pump", "smoke")
    with pytest.raises(TypeError, match=re.escape("unknown Hyper option(s) 'hiden'")):
        Hyper().replace(hiden=3)
