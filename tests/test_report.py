"""The generated report: rows found by run prefix, ablations grouped by the knob each row records."""

import pytest

from fmctd_dist.records import Table
from fmctd_dist.registry import tables
from fmctd_dist.evaluation.report import ABLATIONS, \
    ablation_summary, ablation_table, current_rows, fill_markers, glance_table, load_rows, paper_table, merge_rows
from fmctd_dist.evaluation.results import ResultStore


def row(task, seed, success, t=1.0, method="fast-mctd", env="pointmaze-giant", **knobs):
    return {"method": method, "env": env, "task": task, "seed": seed, "success": success, "plan_time_s": t,
            "denoise_share": 0.5, "call_share": 0.99, "timed_out": False, "expansions": 100, "iterations": 3,
            **knobs}


def test_rows_are_found_by_run_prefix_including_nested_runs(tmp_path):
    ResultStore(tmp_path, "main").write(row(1, 0, True, env="pointmaze-medium"))
    ResultStore(tmp_path, "ablate-k/10").write(row(1, 0, True, parallel=10))
    ResultStore(tmp_path, "ablate-k/200").write(row(1, 0, False, parallel=200))
    ResultStore(tmp_path, "ablate-kx/1").write(row(1, 0, False, parallel=1))  # not under "ablate-k/"
    assert [r["run"] for r in load_rows(tmp_path, "main")] == ["main"]
    assert sorted(r["run"] for r in load_rows(tmp_path, "ablate-k")) == ["ablate-k/10", "ablate-k/200"]
    assert len(load_rows(tmp_path)) == 4


def test_ablation_groups_by_the_recorded_knob_not_the_run_name():
    rows = [row(k, s, k != 1 or v == 10, t=float(v), parallel=v) for v in (1, 10, 200) for k in (1, 2) for s in (0, 1)]
    summary = ablation_summary(rows, "parallel")
    assert [s["value"] for s in summary] == [1, 10, 200]
    assert ([s["success"] for s in summary] == [50, 100, 50]
            and [s["plan_time_s"] for s in summary] == [1.0, 10.0, 200.0])
    ab = next(a for a in ABLATIONS if a.knob == "parallel")
    table = ablation_table(ab, rows)
    assert "| 1 | fast-mctd / giant | 4 (2 x 2) | 50 ± 0 | 1.00 ± 0.00 | 0.01x |" in table  # K=1 is not "True"
    assert "| 10 | fast-mctd / giant | 4 (2 x 2) | 100 ± 0 | 10.00 ± 0.00 | 0.05x |" in table
    assert "| 200 | fast-mctd / giant | 4 (2 x 2) | 50 ± 0 | 200.00 ± 0.00 | 1.00x |" in table


def test_paper_table_lists_every_method_and_marks_what_was_not_run():
    table = paper_table([row(k, s, True, env="pointmaze-medium") for k in (1, 2) for s in (0, 1)], tables()["maze"])
    assert "| fast-mctd | pointmaze-medium | 4 (2 x 2) | 100 ± 0 |" in table
    assert "| mctd | pointmaze-giant | not run |" in table and "100 ± 0 / 264.2 ± 33.8 s" in table
    assert "50.0% / 99.0%" in table


def test_markers_replace_only_their_block_and_a_missing_block_is_an_error():
    doc = "intro\n<!-- report:maze -->\nold\n<!-- /report:maze -->\noutro\n"
    out = fill_markers(doc, {"maze": "| new |"})
    assert out == "intro\n<!-- report:maze -->\n| new |\n<!-- /report:maze -->\noutro\n"
    assert fill_markers(out, {"maze": "| new |"}) == out  # idempotent
    with pytest.raises(KeyError, match="report:ablate-w"):
        fill_markers(doc, {"ablate-w": "x"})


def test_merge_keeps_committed_rows_and_fresh_rows_replace_the_same_episode():
    committed = [{**row(1, 0, False), "run": "main"}, {**row(2, 0, True), "run": "main"},
                 {**row(1, 0, True), "run": "ablate-k/10"}]
    fresh = [{**row(1, 0, True, t=7.0), "run": "main"}, {**row(3, 0, True), "run": "main"}]
    merged = merge_rows(committed, fresh, "main")
    assert [(r["task"], r["success"], r["plan_time_s"]) for r in merged] == [(1, True, 7.0), (2, True, 1.0),
                                                                               (3, True, 1.0)]
    assert [r["run"] for r in merge_rows(committed, fresh, "ablate-k")] == ["ablate-k/10"]


def test_ablation_compares_settings_within_a_maze_not_across():
    rows = [row(1, 0, True, t=t, env=env, parallel=k)
            for env, times in (("pointmaze-giant", {200: 10.0, 10: 5.0}), ("pointmaze-medium", {200: 2.0, 10: 4.0}))
            for k, t in times.items()]
    summary = ablation_summary(rows, "parallel")
    assert [(s["env"], s["value"]) for s in summary] == [("pointmaze-medium", 10), ("pointmaze-medium", 200),
                                                         ("pointmaze-giant", 10), ("pointmaze-giant", 200)]
    table = ablation_table(next(a for a in ABLATIONS if a.knob == "parallel"), rows)
    assert "| 10 | fast-mctd / medium | 1 (1 x 1) | 100 ± 0 | 4.00 ± 0.00 | 2.00x |" in table
    assert "| 10 | fast-mctd / giant | 1 (1 x 1) | 100 ± 0 | 5.00 ± 0.00 | 0.50x |" in table


def test_antmaze_rows_get_their_own_table_with_the_papers_antmaze_numbers():
    rows = [row(k, 0, k < 3, env="antmaze-medium") for k in (1, 2, 3, 4, 5)]
    table = paper_table(rows, tables()["antmaze"])
    assert "| fast-mctd | antmaze-medium | 5 (5 x 1) | 40 ± 0 |" in table
    assert "98 ± 6 / 2.2 ± 0.1 s" in table  # the paper's AntMaze Fast-MCTD, not its PointMaze 100 ± 0 / 3.6 s
    assert "| mctd | antmaze-giant | not run | | | | | 94 ± 9 / 214.5 ± 11.0 s |" in table
    assert "pointmaze" not in table


@pytest.mark.parametrize("times", [[4.56], [4.48, 4.64], [2.4, 12.8, 264.0], [0.9, 1.1, 3.0, 30.0, 300.0]])
def test_summary_plot_tick_labels_never_collide(times):
    """One method over 4.48-4.64 s used to get a log axis whose labels overlapped (issue 18)."""
    import matplotlib.pyplot as plt

    from fmctd_dist.evaluation.plots import success_vs_time_figure

    methods = ["fast-mctd", "s-mctd", "p-mctd", "mctd", "diffuser"]
    summary = [{"method": methods[i], "env": "pointmaze-medium", "plan_time_s": t, "plan_time_std": 0.02 * t,
                "success": 90.0, "success_std": 5.0, "variant": ""} for i, t in enumerate(times)]
    fig = success_vs_time_figure(summary)
    ax = fig.axes[0]
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    labels = [t for t in ax.get_xticklabels() + ax.get_xminorticklabels() if t.get_text() and t.get_visible()]
    lo, hi = ax.get_xlim()
    labels = [t for t in labels if lo <= t.get_position()[0] <= hi]
    boxes = sorted((t.get_window_extent(renderer) for t in labels), key=lambda b: b.x0)
    assert len(boxes) >= 2, [t.get_text() for t in labels]  # the axis says where the points sit
    assert all(a.x1 <= b.x0 for a, b in zip(boxes, boxes[1:])), [t.get_text() for t in labels]
    assert ax.get_xscale() == ("log" if max(times) / min(times) >= 4 else "linear")
    plt.close(fig)


def test_paper_cells_cover_the_robot_table():
    """The cube rows print the paper's robot-table numbers (with its stds) beside ours."""
    from fmctd_dist.evaluation.paper import paper_cell

    assert paper_cell("fast-mctd-replan", "cube-single") == "100 ± 0 / 3.0 ± 0.2 s"
    assert paper_cell("mctd-replan", "cube-triple") == "40 ± 21 / 102.0 ± 6.9 s"
    assert paper_cell("fast-mctd", "pointmaze-giant") == "100 ± 0 / 2.4 ± 0.1 s"
    assert paper_cell("fast-mctd", "cube-single") == "–"  # the paper ran only replanning searches on cubes


def test_robot_table_takes_each_episode_of_todays_default_config_once():
    def cube(run, task, seed, chash, t=1.0, method="fast-mctd-replan", env="cube-double"):
        return {**row(task, seed, True, t=t, method=method, env=env), "run": run, "config_hash": chash,
                "checkpoint_digest": "c" * 16, "episode_time_limit": 0.0}

    hashes = {("fast-mctd-replan", "cube-double"): "now"}
    rows = ([cube("grid-s9", k, s, "now", t=9.0) for k in (1, 2) for s in (0, 1)]  # an early look: seeds 0-1
            + [cube("grid-s12", k, s, "now", t=2.0) for k in (1, 2) for s in range(4)]  # the grid: seeds 0-3
            + [cube("ablate", 1, 0, "other")]  # another config: not today's default
            + [cube("grid-s12", 1, 0, "now", method="s-mctd-replan")]  # no default hash known for it
            + [cube("grid-s12", 1, s, "now") for s in (4, 5)])  # seeds 4-5 stopped after task 1
    cur, dropped = current_rows(rows, hashes)
    assert len(cur) == 8 and {r["run"] for r in cur} == {"grid-s12"}  # duplicates from the larger run
    assert {r["seed"] for r in cur} == {0, 1, 2, 3}  # a seed counts only with every task
    table = paper_table(cur, tables()["robot"], dropped)
    assert ("| fast-mctd-replan | cube-double | 8 (2 x 4; 2 more of unfinished seeds not counted) | 100 ± 0 | "
            "2.00 ± 0.00 |") in table
    assert "77 ± 11 / 5.9 ± 1.7 s" in table  # the paper's cell beside ours
    assert "| mctd-replan | cube-triple | not run |" in table and "| mctd | " not in table


def test_robot_table_marks_lines_on_weights_that_are_no_longer_shipped():
    """A config names its checkpoint by path: rows made before the weights there were replaced keep the
    config hash, and only their digest tells them apart. Such a line says so, and shows only where no line is on
    today's weights; lines on today's weights do not."""
    def cube(task, seed, digest, method):
        return {**row(task, seed, True, method=method, env="cube-triple"), "run": "grid", "config_hash": "now",
                "checkpoint_digest": digest, "episode_time_limit": 0.0}

    methods = ("s-mctd-replan", "fast-mctd-replan")
    hashes = {(m, "cube-triple"): "now" for m in methods}
    rows = ([cube(k, s, "old" * 6, "s-mctd-replan") for k in (1, 2) for s in (0, 1)]
            + [cube(k, s, d * 16, "fast-mctd-replan") for d in "ab" for k in (1, 2) for s in (0, 1)])
    cur, dropped = current_rows(rows, hashes)
    shipped = {(m, "cube-triple"): "b" * 16 for m in methods}
    table = paper_table(cur, tables()["robot"], dropped, shipped)
    assert "| s-mctd-replan (older weights oldoldol; shipped: bbbbbbbb) | cube-triple | 4 (2 x 2) |" in table
    # a line on today's weights hides the same config's lines on replaced ones (they stay in the rows)
    assert "| fast-mctd-replan | cube-triple | 4 (2 x 2) |" in table and "aaaaaaaa" not in table
    unknown = paper_table(cur, tables()["robot"], dropped)  # nothing known of what is shipped: every line
    assert unknown.count("older weights") == 0 and "| fast-mctd-replan [config now, ckpt aaaaaaaa] |" in unknown


def run_report(tmp_path, doc_text: str):
    """jobs/report.py on the rows under ``tmp_path/res``, into a fresh doc holding ``doc_text``; returns the doc."""
    import subprocess
    import sys

    from fmctd_dist.config import REPO_ROOT

    doc = tmp_path / "docs" / "results.md"
    doc.parent.mkdir()
    doc.write_text(doc_text)
    out = subprocess.run([sys.executable, "jobs/report.py", f"results={tmp_path / 'res'}", f"doc={doc}",
                          f"figures={tmp_path / 'fig'}"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return doc


def test_report_archives_rows_of_hand_written_sections_without_their_trajectories(tmp_path):
    """jobs/report.py keeps the rows of runs cited by hand-written sections (cube, visual, benches) in
    eval_rows.parquet, scalars only, beside the tabulated runs; uncited runs stay out."""
    import pyarrow.parquet as pq

    cube = {**row(1, 0, True, method="fast-mctd-replan", env="cube-single"), "plan_cubes": [0.1, 0.2],
            "traj_cubes": [0.3], "goal_cubes": [1.0, 2.0, 3.0]}
    ResultStore(tmp_path / "res", "cube-yaw-s9").write(cube)
    ResultStore(tmp_path / "res", "scratch").write(row(2, 0, False))
    doc = run_report(tmp_path, "# Results\n")
    rows = pq.read_table(doc.parent / "eval_rows.parquet").to_pylist()
    assert [(r["run"], r["env"]) for r in rows] == [("cube-yaw-s9", "cube-single")]
    assert "plan_cubes" not in rows[0] and "traj_cubes" not in rows[0] and rows[0]["goal_cubes"] == [1.0, 2.0, 3.0]


def test_report_marks_maze_lines_whose_weights_were_replaced(tmp_path):
    """jobs/report.py gives the maze table today's checkpoint digests: a line of run ``main`` made on weights
    that were replaced at the same path says "older weights"; a line on today's weights does not."""
    import json

    from fmctd_dist.config import REPO_ROOT, load_config
    from fmctd_dist.evaluation.identity import config_hash

    today = json.loads((REPO_ROOT / "checkpoints/pointmaze-medium-h5/manifest.json").read_text())["digest"]
    for digest, method, seed in ((today, "fast-mctd", 0), ("0" * 16, "s-mctd", 0), (today, "fast-mctd", 1)):
        default = config_hash(load_config(["env=pointmaze-medium", f"method={method}"]))
        for k in (1, 2):
            ResultStore(tmp_path / "res", "main").write(
                {**row(k, seed, True, method=method, env="pointmaze-medium"),
                 "config_hash": default if seed == 0 else "h" * 16,  # seed 1: made at other settings
                 "checkpoint_digest": digest, "episode_time_limit": 0.0})
    text = run_report(tmp_path, "# Results\n<!-- report:maze -->\n<!-- /report:maze -->\n").read_text()
    assert "| fast-mctd | pointmaze-medium | 2 (2 x 1) |" in text  # the tables hold today's default config only
    assert f"| s-mctd (older weights 00000000; shipped: {today[:8]}) | pointmaze-medium | 2 (2 x 1) |" in text


def test_an_episode_rerun_on_new_weights_keeps_its_earlier_row_under_a_superseded_run():
    from fmctd_dist.evaluation.report import superseded

    old = [{**row(k, 0, False), "run": "main", "config_hash": "c" * 16, "checkpoint_digest": "a" * 16} for k in (1, 2)]
    new = [{**row(1, 0, True), "run": "main", "config_hash": "c" * 16, "checkpoint_digest": "b" * 16},
           {**row(2, 0, False), "run": "main", "config_hash": "c" * 16, "checkpoint_digest": "a" * 16}]  # same identity
    kept = superseded(old, new)
    assert [(r["run"], r["task"], r["success"]) for r in kept] == [("superseded/main@cccccccc-aaaaaaaa", 1, False)]
    merged = merge_rows(old + kept, new, "main")  # the table's run holds today's rows only
    assert [(r["task"], r["checkpoint_digest"][0]) for r in merged] == [(1, "b"), (2, "a")]
    assert superseded(old + kept, new) == kept  # a second report adds nothing


def test_ablation_lines_on_weights_no_longer_shipped_say_so():
    rows = [row(k, 0, True, parallel=v, checkpoint_digest=d, config_hash="c" * 16, episode_time_limit=0.0)
            for v, d in ((10, "a" * 16), (200, "b" * 16)) for k in (1, 2)]
    ab = next(a for a in ABLATIONS if a.knob == "parallel")
    table = ablation_table(ab, rows, shipped={"b" * 16})
    assert "| 10 | fast-mctd / giant (older weights aaaaaaaa) | 2 (2 x 1) |" in table
    assert "| 200 | fast-mctd / giant | 2 (2 x 1) |" in table
    assert "older weights" not in ablation_table(ab, rows)  # nothing known about what is shipped


def test_glance_table_shows_todays_largest_line_per_cell_beside_the_paper():
    """One cell per (method, env): the line on today's weights with the most episodes, a count when under 50,
    a dagger when every line is on replaced weights, '‡' for what ran only at other settings, '–' for what was
    not run; each column its own methods."""
    def r(task, seed, ok, method, env, digest):
        return {**row(task, seed, ok, method=method, env=env), "config_hash": "c" * 16, "checkpoint_digest": digest,
                "episode_time_limit": 0.0}

    rows = ([r(k, s, k != 5 or s < 6, "fast-mctd", "pointmaze-giant", "new") for k in range(1, 6) for s in range(10)]
            # older and smaller: not shown
            + [r(k, 0, False, "fast-mctd", "pointmaze-giant", "old") for k in range(1, 6)]
            + [r(k, s, True, "s-mctd", "pointmaze-giant", "old") for k in (1, 2) for s in (0, 1)]
            + [r(1, 0, True, "fast-mctd-replan", "cube-single", "new")])
    shipped = {("fast-mctd", "pointmaze-giant"): "new", ("s-mctd", "pointmaze-giant"): "new",
               ("fast-mctd-replan", "cube-single"): "new"}
    maze, cube = ["mctd", "s-mctd", "fast-mctd"], ["mctd-replan", "s-mctd-replan", "fast-mctd-replan"]
    point = Table("maze", ("pointmaze-giant",), maze, {}, columns=("point giant",))
    arm = Table("robot", ("cube-single",), cube, {}, columns=("cube single",))
    table = glance_table(rows, [point, arm], shipped, {("mctd", "pointmaze-giant")})
    assert table.splitlines()[0] == "| method | point giant | cube single |"
    assert "| fast-mctd / fast-mctd-replan | 92 / 100 | 100 (1) / 100 |" in table
    assert "| s-mctd / s-mctd-replan | 100 (4) † / 100 | – / 100 |" in table
    assert "| mctd / mctd-replan | ‡ / 100 | – / 100 |" in table  # run, but only at settings other than today's


def test_visual_table_reads_each_method_at_its_default_and_the_shipped_weights_only():
    from fmctd_dist.config import load_config
    from fmctd_dist.evaluation.identity import identity_columns
    from fmctd_dist.families.visual.table import default_config, search_statuses, shipped, training, visual_table

    env = "visual-pointmaze-large"
    planner, invdyn = shipped("fast-mctd", env)
    assert planner and invdyn  # the committed checkpoints
    ours = {"checkpoint_digest": planner, "policy_digest": invdyn}
    default = identity_columns(default_config("fast-mctd", env))
    named = identity_columns(load_config([f"env={env}", "method=fast-mctd",  # the shipped weights, by their path
                                          f"checkpoint=checkpoints/{default_config('fast-mctd', env).run_name}"]))
    plain = identity_columns(load_config([f"env={env}", "method=fast-mctd", "diffusion.boundary_guidance=0"]))
    assert named["config_hash"] != default["config_hash"]
    rows = [{**row(k, s, k == 1, env=env, jump=5), **default, **ours, "run": "visual-x",
             "plan_status": "early_stop" if k == 1 else "stay,stay"}  # task 2 replanned once, both searches empty
            for k in (1, 2) for s in (0, 1)]
    rows += [{**row(k, 2, True, env=env, jump=5), **named, **ours, "run": "visual-y", "plan_status": "achieved"}
             for k in (1, 2)]
    rows += [{**row(k, 3, True, env=env, jump=5), **plain, **ours, "run": "visual-z"} for k in (1, 2)]  # other setting
    rows += [{**row(k, 4, True, env=env, jump=5), **default, "checkpoint_digest": "older", "policy_digest": invdyn,
              "run": "visual-z"} for k in (1, 2)]  # older weights
    table = visual_table(rows)
    saw = training(default_config("fast-mctd", env))
    assert ("| fast-mctd | large | 6 (2 x 3, 2 of 5 tasks so far) | 67 ± 24 | 100/33 | 1.0 ± 0.0 | "
            f"stay 4, early_stop 2, achieved 2 | `{planner[:8]}`, H=5 | {saw} | "
            "[z, x, y] frames, boundary guidance 8 | `visual-x`, `visual-y` | 32 / 5.1 s |") in table
    assert saw.endswith("%), 100 episodes")  # its latent store: 100 train episodes
    assert table.count("| fast-mctd | large |") == 1  # one line per method and maze
    assert "| s-mctd | large | no episodes at the default yet |" in table
    assert ("| diffuser | medium | no episodes at the default yet | | | | | | 0.1 M windows (9.1%), 20 episodes | "
            "latent frames (the paper's) |") in table
    assert search_statuses([{"plan_status": "plan,plan"}, {"plan_status": "plan"}]) == "no search"  # DF, Diffuser


def test_an_env_file_sets_one_methods_defaults_after_the_method_file(tmp_path, monkeypatch):
    import pytest

    from fmctd_dist.config import load_config, loader
    from fmctd_dist.errors import ConfigError

    def config(method: str, *words: str):
        return load_config(["env=visual-pointmaze-medium", f"method={method}", *words])

    assert config("fast-mctd").diffusion.boundary_guidance == 8.0  # no entry: the env file's value
    assert config("diffuser").diffusion.boundary_guidance == 0.0  # its methods: entry, after the method file
    assert not config("diffuser").visual.plan_xy and config("mctd").visual.plan_xy
    assert config("diffuser", "visual.episodes=100").visual.episodes == 100  # the command's words come last
    assert load_config(["env=pointmaze-medium", "method=fast-mctd"]).diffusion.boundary_guidance == 0.0
    (tmp_path / "env").mkdir()
    (tmp_path / "method").mkdir()
    (tmp_path / "env" / "pointmaze-medium.yaml").write_text("methods:\n  fast-mcdt: {jump: 5}\n")
    (tmp_path / "method" / "fast-mctd.yaml").write_text("jump: 5\n")
    monkeypatch.setattr(loader, "CONFIG_DIR", tmp_path)
    with pytest.raises(ConfigError, match="methods.fast-mcdt names no method.*fast-mctd"):
        load_config(["env=pointmaze-medium", "method=fast-mctd"])


def test_plan_statuses_reads_back_what_the_tally_writes():
    from collections import Counter

    from fmctd_dist.evaluation.plan_tally import PlanTally, plan_statuses

    written = PlanTally(plans=4, statuses=["stay", "achieved", "stay", "early_stop"]).columns()
    assert plan_statuses(written) == Counter(stay=2, achieved=1, early_stop=1)
    assert list(plan_statuses(written)) == ["stay", "achieved", "early_stop"]  # first-seen order, for reports
    assert plan_statuses(PlanTally().columns()) == Counter()  # no plan yet
    assert plan_statuses({}) == Counter() == plan_statuses({"plan_status": None})  # rows that predate the column


def test_an_episodes_tally_seeds_its_plans_and_stops_at_its_time_limit():
    import numpy as np

    from fmctd_dist.config import load_config
    from fmctd_dist.evaluation.plan_tally import PlanTally
    from fmctd_dist.planners.base import PlanOutput, plan_seed

    class Slow:  # each plan takes 2 s of planning time and remembers its seed
        seeds: list[int] = []

        def plan(self, start, goal, seed):
            self.seeds.append(seed)
            return PlanOutput(np.full((3, 2), len(self.seeds), np.float32), "stay", 2.0, 1.0)

    cfg, planner = load_config(["eval.episode_time_limit=3"]), Slow()
    tally = PlanTally.episode(cfg, 4, 7)
    assert tally.plan(planner, np.zeros(2), np.ones(2)) is not None  # 2 s: within the limit
    assert tally.plan(planner, np.zeros(2), np.ones(2)) is None and tally.timed_out  # 4 s: over it
    assert planner.seeds == [plan_seed(cfg.seed, 4, 7, k) for k in range(2)] and tally.first[0, 0] == 1
    row = tally.row(True, 12)
    assert list(row)[:7] == ["method", "env", "task", "seed", "success", "timed_out", "env_steps"]
    assert (row["task"], row["seed"], row["success"], row["plans"], row["plan_time_s"]) == (4, 7, False, 2, 4.0)
    assert row["episode_time_s"] >= 0 and list(row)[-1] == "episode_time_s"
