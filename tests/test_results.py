"""Result rows: atomic per-episode files, resume keys, and the paper-style summary."""

from fmctd_dist.evaluation.results import ResultStore, markdown_table, summarise


def row(task, seed, success, t=1.0, method="fast-mctd"):
    return {"method": method, "env": "pointmaze-large", "task": task, "seed": seed, "success": success,
            "plan_time_s": t, "denoise_share": 0.9, "timed_out": False}


def test_store_round_trip_and_keys(tmp_path):
    store = ResultStore(tmp_path, "r")
    assert not store.has("fast-mctd", "pointmaze-large", 1, 0)
    store.write(row(1, 0, True))
    store.write(row(1, 0, False))  # same key: replaced, never duplicated
    assert store.has("fast-mctd", "pointmaze-large", 1, 0)
    assert [r["success"] for r in store.rows()] == [False]
    assert not list(tmp_path.rglob("*.tmp"))


def test_std_is_over_seeds_like_the_paper():
    rows = [row(k, s, k != 2, t=1.0 + s) for k in range(1, 6) for s in range(10)]
    (s,) = summarise(rows)
    assert s["success"] == 80 and s["success_std"] == 0  # 100/0/100/100/100 at every seed
    assert s["per_task"] == {1: 100, 2: 0, 3: 100, 4: 100, 5: 100}
    assert abs(s["plan_time_s"] - 5.5) < 1e-12 and s["seeds"] == 10
    table = markdown_table([s])
    assert "| fast-mctd | pointmaze-large | 50 | 80 ± 0 |" in table and "80 ± 0 / 4.1 ± 0.4 s" in table
