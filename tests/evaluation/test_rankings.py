"""Rankings, averages and timings (paper Tables 2–7) on hand-made tables with hand-computed answers."""

from __future__ import annotations

import pytest

from dmtrack.evaluation.rankings import (
    CRITERIA,
    competition_rank,
    group_rows,
    mean_defined,
    overall_averages,
    ranking_table,
    sequence_ranks,
    timing_table,
    tracked_fraction,
    value_of,
)

ROT, TRANS, TRACKED = "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "tracked_frames"


def row(seq, feat, tracked, total, rot, trans, ate=None, **extra):
    return {"sequence": seq, "feature": feat, TRACKED: tracked, "total_frames": total, ROT: rot, TRANS: trans,
            "ate_rmse": ate, **extra}  # fmt: skip


# s1: a tie on tracked frames (A, B) and on the translation angle (A, B);
# s2: B crashed (everything missing), A has no RPE (evaluation failed), C lost frames;
# s3: nobody has an RPE value (NaN / inf / None) and C has no row at all.
TABLE = [
    row("s1", "A", 100, 100, 1.0, 3.0, 0.1),
    row("s1", "B", 100, 100, 2.0, 3.0),
    row("s1", "C", 50, 100, 0.5, 5.0),
    row("s2", "A", 80, 80, None, None, 0.3),
    row("s2", "B", None, None, None, None),
    row("s2", "C", 60, 80, 4.0, 2.0),
    row("s3", "A", 10, 40, float("nan"), float("inf")),
    row("s3", "B", 40, 40, None, None),
]


def test_competition_rank_1224():
    assert competition_rank([3.0, 1.0, 1.0, 2.0]) == [4, 1, 1, 3]
    assert competition_rank([10, 30, 30, 20], higher_is_better=True) == [4, 1, 1, 3]
    assert competition_rank([5.0, 5.0, 5.0]) == [1, 1, 1]
    assert competition_rank([]) == []


def test_competition_rank_missing_values_rank_last_and_tie():
    assert competition_rank([0.5, None, 0.2, float("nan"), 0.5]) == [2, 4, 1, 4, 2]
    assert competition_rank([None, 7, float("inf")], higher_is_better=True) == [2, 1, 2]
    assert competition_rank([None, None]) == [1, 1]  # sequence_ranks leaves such a criterion out


def test_value_of_and_mean_defined():
    assert value_of({"x": 2}, "x") == 2.0
    assert value_of({"x": "3.5"}, "x") == 3.5
    for bad in (None, float("nan"), float("-inf"), "abc", True):
        assert value_of({"x": bad}, "x") is None
    assert value_of({}, "x") is None and value_of(None, "x") is None
    assert mean_defined([1.0, None, 3.0, float("nan")]) == (2.0, 2)
    assert mean_defined([None]) == (None, 0)
    assert tracked_fraction({TRACKED: 30, "total_frames": 40}) == 0.75
    assert tracked_fraction({TRACKED: 30, "total_frames": 0}) is None


def test_sequence_ranks_hand_computed():
    ranks = sequence_ranks(TABLE)
    assert ranks["s1"]["A"] == {TRACKED: 1, ROT: 2, TRANS: 1}
    assert ranks["s1"]["B"] == {TRACKED: 1, ROT: 3, TRANS: 1}
    assert ranks["s1"]["C"] == {TRACKED: 3, ROT: 1, TRANS: 3}
    assert ranks["s2"]["A"] == {TRACKED: 1, ROT: 2, TRANS: 2}
    assert ranks["s2"]["B"] == {TRACKED: 3, ROT: 2, TRANS: 2}  # crashed: last, tied with A's missing RPE
    assert ranks["s2"]["C"] == {TRACKED: 2, ROT: 1, TRANS: 1}
    assert ranks["s3"]["A"] == {TRACKED: 2, ROT: None, TRANS: None}  # no RPE on s3 at all: not ranked
    assert ranks["s3"]["B"] == {TRACKED: 1, ROT: None, TRANS: None}
    assert ranks["s3"]["C"] == {TRACKED: 3, ROT: None, TRANS: None}  # no row = missing = last


def test_ranking_table_wins_and_average_ranking():
    table = {fr.feature: fr for fr in ranking_table(TABLE)}
    assert list(table) == ["A", "B", "C"]
    assert table["A"].wins == {TRACKED: 2, ROT: 0, TRANS: 1}
    assert table["B"].wins == {TRACKED: 2, ROT: 0, TRANS: 1}
    assert table["C"].wins == {TRACKED: 0, ROT: 2, TRANS: 1}
    assert table["A"].average_rank == pytest.approx({TRACKED: 4 / 3, ROT: 2.0, TRANS: 1.5})
    assert table["B"].average_rank == pytest.approx({TRACKED: 5 / 3, ROT: 2.5, TRANS: 1.5})
    assert table["C"].average_rank == pytest.approx({TRACKED: 8 / 3, ROT: 1.0, TRANS: 2.0})
    assert table["A"].sequences == {TRACKED: 3, ROT: 2, TRANS: 2}


def test_ranking_table_feature_subset_and_order():
    table = ranking_table(TABLE, features=["C", "A"])  # B is not a competitor
    assert [fr.feature for fr in table] == ["C", "A"]
    by = {fr.feature: fr for fr in table}
    # s1 tracked: A 100 > C 50; s2: A 80 > C 60; s3: A 10, C missing → A wins all three
    assert by["A"].wins[TRACKED] == 3 and by["C"].average_rank[TRACKED] == 2.0
    # rotation: s1 C 0.5 < A 1.0; s2 C 4.0, A missing → C wins both
    assert by["C"].wins[ROT] == 2 and by["A"].average_rank[ROT] == 2.0


def test_duplicate_rows_raise():
    with pytest.raises(ValueError, match="two rows"):
        sequence_ranks([*TABLE, row("s1", "A", 1, 1, 1.0, 1.0)])


def test_overall_averages_hand_computed():
    av = {a.feature: a for a in overall_averages(TABLE)}
    a, b, c = av["A"], av["B"], av["C"]
    assert (a.runs, b.runs, c.runs) == (3, 3, 2)
    assert a.tracked_fraction == pytest.approx(0.75) and a.n_tracked == 3  # (1 + 1 + 0.25) / 3
    assert a.tracked_frames == pytest.approx(190 / 3)
    assert (a.rpe_rot, a.n_rpe_rot, a.rpe_trans, a.n_rpe_trans) == (1.0, 1, 3.0, 1)  # NaN/inf/None left out
    assert (a.ate, a.n_ate) == (pytest.approx(0.2), 2)
    assert b.tracked_fraction == 1.0 and b.n_tracked == 2  # the crash has no value
    assert b.tracked_frames == 70.0
    assert c.tracked_fraction == pytest.approx(0.625) and c.tracked_frames == 55.0
    assert (c.rpe_rot, c.n_rpe_rot, c.rpe_trans) == (pytest.approx(2.25), 2, pytest.approx(3.5))
    assert c.ate is None and c.n_ate == 0
    # only s1 has both RPE values for every feature
    assert [x.n_common for x in (a, b, c)] == [1, 1, 1]
    assert (a.common_rpe_rot, b.common_rpe_rot, c.common_rpe_rot) == (1.0, 2.0, 0.5)
    assert (a.common_rpe_trans, b.common_rpe_trans, c.common_rpe_trans) == (3.0, 3.0, 5.0)


def test_overall_averages_without_common_sequences():
    rows = [row("s1", "A", 5, 10, 1.0, 2.0), row("s1", "B", 5, 10, None, None)]
    av = overall_averages(rows)
    assert av[0].n_common == 0 and av[0].common_rpe_rot is None and av[0].rpe_rot == 1.0


def timed(seq, feat, total, processed, feature, io, tracking, mapping, wall):
    return {"sequence": seq, "feature": feat, "total_frames": total, "processed_frames": processed,
            "feature_ms": feature, "io_ms": io, "tracking_ms": tracking, "mapping_ms": mapping,
            "wall_s": wall}  # fmt: skip


def test_timing_table_frame_weighted():
    rows = [
        timed("s1", "A", 100, 100, 10.0, 1.0, 20.0, 30.0, 10.0),
        timed("s2", "A", 80, 80, 20.0, 1.0, 40.0, 30.0, 10.0),
        timed("s3", "A", 40, 10, 10.0, 1.0, 20.0, 30.0, 1.0),  # lost after 10 processed frames
        {"sequence": "s1", "feature": "B", "total_frames": 50},  # crashed: no timings
    ]
    t = {x.feature: x for x in timing_table(rows)}
    a = t["A"]
    assert (a.runs, a.frames) == (3, 190)
    assert a.feature_ms == pytest.approx(2700 / 190)
    assert a.tracking_ms == pytest.approx(5400 / 190)
    assert a.io_ms == pytest.approx(1.0) and a.mapping_ms == pytest.approx(30.0)
    total = 2700 / 190 + 1.0 + 5400 / 190 + 30.0
    assert a.total_ms == pytest.approx(total) and a.fps == pytest.approx(1000 / total)
    assert a.wall_fps == pytest.approx(190 / 21)
    b = t["B"]
    assert (b.runs, b.frames, b.total_ms, b.fps, b.wall_fps) == (0, 0, None, None, None)


def test_timing_without_processed_frames_uses_total_frames():
    rows = [timed("s1", "A", 10, None, 1.0, 0.0, 1.0, 1.0, 1.0), timed("s2", "A", 30, None, 5.0, 0.0, 1.0, 1.0, 1.0)]
    (a,) = timing_table(rows)
    assert a.frames == 40 and a.feature_ms == pytest.approx((10 * 1 + 30 * 5) / 40)


def test_group_rows_keeps_order():
    rows = [{"dataset": "K", "i": 0}, {"dataset": "7", "i": 1}, {"dataset": "K", "i": 2}, {"i": 3}]
    g = group_rows(rows)
    assert list(g) == ["K", "7", "unknown"]
    assert [r["i"] for r in g["K"]] == [0, 2]


def test_criteria_are_the_papers():
    assert [(c.key, c.higher_is_better) for c in CRITERIA] == [(TRACKED, True), (ROT, False), (TRANS, False)]


def test_aggregate_seeds_medians_ranges_and_worst_seed():
    from dmtrack.evaluation.rankings import aggregate_seeds, median_range

    assert median_range([3.0, None, float("nan"), 1.0, 2.0, 10.0]) == (2.5, 1.0, 10.0, 4)
    assert median_range([12, 9, 12]) == (12, 9, 12, 3) and median_range([None]) == (None, None, None, 0)
    runs = [
        row("s1", "A", 100, 100, 4.0, 1.0, seed=2, status="ok"),
        row("s1", "A", 60, 100, 1.0, 3.0, seed=0, status="lost", lost_at=60),
        row("s1", "A", 100, 100, 2.0, None, seed=1, status="ok"),
        row("s1", "B", 100, 100, 3.0, 5.0, seed=0, status="ok", dataset="D"),
    ]
    a, b = aggregate_seeds(runs)
    assert (a["sequence"], a["feature"], a["seeds"], a["runs"]) == ("s1", "A", [0, 1, 2], 3)
    assert (a["n_ok"], a["n_lost"], a["n_failed"]) == (2, 1, 0)
    assert (a[TRACKED], a[f"{TRACKED}_min"], a[f"{TRACKED}_max"]) == (100, 60, 100)
    assert (a[ROT], a[f"{ROT}_min"], a[f"{ROT}_max"], a[f"{ROT}_n"]) == (2.0, 1.0, 4.0, 3)
    assert (a[TRANS], a[f"{TRANS}_n"]) == (2.0, 2)  # median of the two defined values
    assert (a["worst_seed"], a["status"], a["lost_at"], a["worst_tracked_frames"]) == (0, "lost", 60, 60)
    # one run per cell: the cell row carries the run's values, so the tables are those of the runs
    assert (b[ROT], b[f"{ROT}_min"], b[f"{ROT}_max"], b["status"], b["dataset"]) == (3.0, 3.0, 3.0, "ok", "D")
    # rankings on the medians: A's rotation median 2.0 beats B's 3.0 (A's seed 2 alone, 4.0, would lose)
    assert sequence_ranks([a, b])["s1"]["A"][ROT] == 1
    assert overall_averages([a, b])[0].tracked_fraction == pytest.approx(1.0)  # median of 1.0, 0.6, 1.0
