"""The static localizer's failures counted over several filter draws (benchmarks.draws)."""

from benchmarks.draws import count, pairs


def _doc(draw, lost):
    """A bench_gatmo_sim output: ``lost`` maps hall seed -> (static, full stack) time lost."""
    overrides = [f"seed={draw}", "gatmo.still_to_gamma=true"] if draw else []
    rows = [{"seed": s, "static_lost": st, "gatmo_lost": g, "static_ate_m": 1.0,
             "gatmo_ate_m": 0.5} for s, (st, g) in lost.items()]
    return {"rows": rows, "total": {"overrides": overrides}}


def test_each_seed_and_draw_is_one_pair_named_by_its_filter_seed():
    recs = pairs([_doc(0, {1: (0.0, 0.0)}), _doc(10, {1: (0.2, 0.0), 2: (0.0, 0.0)})])
    assert [(r["seed"], r["draw"]) for r in recs] == [(1, 0), (1, 10), (2, 10)]


def test_failures_kept_brought_and_worse_are_told_apart():
    recs = pairs([
        _doc(0, {1: (0.30, 0.00),    # static lost, full stack kept it
                 2: (0.30, 0.20),    # lost on both sides (a failure that still happens)
                 3: (0.00, 0.12),    # the full stack lost where the static was not
                 4: (0.020, 0.025)}),  # neither lost; 0.5 points more: within the margin
        _doc(20, {3: (0.00, 0.00),
                  4: (0.000, 0.030)}),  # neither lost, but 3 points worse
    ])
    n = count(recs, lost_share=0.05, margin=0.01)
    assert n["pairs"] == 6 and n["seeds"] == 4 and n["draws"] == [0, 20]
    assert n["static_lost"] == 2 and n["gatmo_lost"] == 2
    assert n["both_lost"] == 1 and n["new_lost"] == 1
    assert n["worse"] == 2 and n["worse_by_seed"] == {3: [0], 4: [20]}
