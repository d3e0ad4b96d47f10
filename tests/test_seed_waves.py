"""Further waves of seeds in the plan's time (:func:`nnfmu.training.seed_runs.further_seeds`, ``train_seeds``'s
``more_within``): more seeds where the first ones stopped early, never a wave that would end past the budget."""

from __future__ import annotations

import pytest

from nnfmu.models import ModelConfig, load_checkpoint
from nnfmu.training import TrainConfig, train_seeds
from nnfmu.training.seed_runs import further_seeds, training_seconds
from tests.test_training import FAST, TINY

pytestmark = pytest.mark.usefixtures("one_thread")


def test_a_further_wave_trains_only_where_it_would_end_within_the_budget_and_the_most_seeds():
    # 2 seeds side by side took 100 s: two more fit in 600 s, up to the most
    assert further_seeds([100.0], 2, 2, 8, 600.0) == (2, "")
    assert further_seeds([100.0, 150.0], 2, 4, 8, 600.0) == (2, "")  # 250 s spent, the next expected at 150 s
    assert further_seeds([100.0, 150.0], 2, 4, 5, 600.0) == (1, "")  # one left to the most
    n, why = further_seeds([250.0, 250.0], 2, 4, 8, 600.0)  # a third wave would end at 750 s
    assert n == 0 and "would end after the 10 minutes" in why
    n, why = further_seeds([10.0] * 4, 2, 8, 8, 600.0)
    assert n == 0 and "the most the plan trains (8)" in why
    assert further_seeds([700.0], 2, 2, 8, 600.0)[0] == 0  # the first wave used the budget (a long record)


def test_seeds_train_in_waves_while_the_time_allows_and_the_choice_is_made_over_all_of_them(valve_tiny, tmp_path):
    gru = ModelConfig(arch="gru", n_u=2, n_y=2, **TINY)
    cfg = TrainConfig(**{**FAST, "epochs": 3})
    out = tmp_path / "w.pt"
    result = train_seeds(valve_tiny, gru, cfg, seeds=2, out=out, jobs=1, more_within=3600.0, most=4)
    assert [r["seed"] for r in result.seeds] == [0, 1, 2, 3]  # waves of one (jobs=1) until the most
    assert sorted(p.name for p in (tmp_path / "w.seeds").iterdir()) == [f"seed-{s}.pt" for s in range(4)]
    note = next(n for n in result.notes if n.startswith("trained 4 seeds in 3 wave(s)"))
    assert "no further wave: the most the plan trains (4)" in note
    trained = [r for r in result.seeds if r["best_epoch"] > 0] or result.seeds
    assert result.valid_nrmse <= min(r["best_valid_nrmse"] for r in trained) + 1e-12  # chosen over all four
    assert [r["seed"] for r in load_checkpoint(out)["summary"]["seeds"]] == [0, 1, 2, 3]
    stamps = [p.stat().st_mtime_ns for p in sorted((tmp_path / "w.seeds").iterdir())]
    again = train_seeds(valve_tiny, gru, cfg, seeds=2, out=out, jobs=1, more_within=3600.0, most=4)
    assert [p.stat().st_mtime_ns for p in sorted((tmp_path / "w.seeds").iterdir())] == stamps  # nothing trained again
    assert again.valid_nrmse == result.valid_nrmse

    # a budget the first wave already spent: no further wave, and the note says why
    spent = training_seconds(tmp_path / "w.seeds" / "seed-0.pt")
    assert spent > 0
    short = train_seeds(valve_tiny, gru, cfg, seeds=2, out=tmp_path / "s.pt", jobs=1, more_within=0.0, most=4)
    assert [r["seed"] for r in short.seeds] == [0, 1]
    assert any("trained 2 seeds in 1 wave(s)" in n and "would end after" in n for n in short.notes)
    plain = train_seeds(valve_tiny, gru, cfg, seeds=2, out=tmp_path / "p.pt", jobs=1)  # more_within None: K seeds
    assert [r["seed"] for r in plain.seeds] == [0, 1] and not any("wave" in n for n in plain.notes)
