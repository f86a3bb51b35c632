"""The campaign engine: same answers on every executor, retries, resume, statistics, and the
``azimut eval`` campaign flags. The Ray tests use a local instance of 2 CPUs and skip where the
``cluster`` extra (ray) is not installed."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from jobs.campaign.args import parse_seeds
from jobs.campaign.engine import CampaignInterrupted, Task, TaskStore, bootstrap_ci, run_tasks, summarize
from jobs.cli import main
from jobs.eval.campaign import draw_kick, episode_tasks

EXECUTORS = ["process", "ray"]


@pytest.fixture(scope="module")
def ray_instance():
    ray = pytest.importorskip("ray")
    import logging

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING)
    yield ray
    ray.shutdown()


@pytest.fixture(params=EXECUTORS)
def executor(request):
    if request.param == "ray":
        request.getfixturevalue("ray_instance")
    return request.param


def _metrics(records):
    return [json.dumps(r["result"]["metrics"], sort_keys=True) for r in records]


def _sum_tasks(seeds, **extra):
    return [Task("campaign_tasks:seeded_sum", {"seed": s}, extra=extra, label=f"s{s}") for s in seeds]


# --------------------------------------------------------------------------- seeds and stats


def test_parse_seeds():
    assert parse_seeds("0-9") == list(range(10))
    assert parse_seeds("0,3,5") == [0, 3, 5]
    assert parse_seeds("0-2, 7") == [0, 1, 2, 7]
    for bad in ("3-1", "a", "1,,2", "-1", "1,1", "0-3,2", "1.5"):
        with pytest.raises(ValueError):
            parse_seeds(bad)


def test_bootstrap_ci_is_seeded_and_matches_the_normal_interval():
    x = np.random.default_rng(1).normal(10.0, 2.0, size=400)
    a = bootstrap_ci(x, seed=3)
    assert a == bootstrap_ci(x, seed=3)
    assert a["mean"] == pytest.approx(np.mean(x)) and a["n"] == 400
    half = 1.96 * np.std(x, ddof=1) / math.sqrt(x.size)  # the normal interval, which the bootstrap approaches
    assert a["lo"] == pytest.approx(a["mean"] - half, abs=0.1 * half)
    assert a["hi"] == pytest.approx(a["mean"] + half, abs=0.1 * half)
    one = bootstrap_ci([2.0, float("nan")])
    assert one == {"mean": 2.0, "lo": 2.0, "hi": 2.0, "n": 1}
    assert bootstrap_ci([float("nan")])["n"] == 0


def test_summarize_groups_and_counts_bools_as_shares():
    rows = [{"controller": c, "track": "t", "seed": s, "err": float(s), "completed": s != 2}
            for c in ("a", "b") for s in range(4)]
    cells = summarize(rows, ("controller", "track"))
    assert [(c["controller"], c["n"]) for c in cells] == [("a", 4), ("b", 4)]
    assert cells[0]["metrics"]["err"]["mean"] == 1.5
    assert cells[0]["metrics"]["completed"]["mean"] == 0.75
    assert cells[0]["metrics"]["err"]["lo"] < 1.5 < cells[0]["metrics"]["err"]["hi"]


def test_task_id_depends_on_the_key_only():
    a = Task("m:f", {"seed": 1, "x": 2.0}, extra={"out": "here"}, label="a b/c")
    b = Task("m:f", {"x": 2.0, "seed": 1}, extra={"out": "there"}, label="a b/c")
    assert a.id == b.id and "/" not in a.id
    assert Task("m:f", {"seed": 2, "x": 2.0}, label="a b/c").id != a.id
    with pytest.raises(ValueError):
        Task("nofunction", {})
    with pytest.raises(TypeError):
        Task("m:f", {"x": object()})


def test_kick_is_drawn_from_the_seed():
    assert draw_kick(3, "paper") == draw_kick(3, "paper")
    k = draw_kick(3, "paper", max_time=4.0)
    assert 1 <= len(k["wheels"]) <= 4 and 0.2 <= abs(k["impulse"]) <= 1.0 and 1 <= k["step"] <= 0.6 * 4.0 / 0.02


# ---------------------------------------------------------------------------------- engine


def test_serial_retries_an_exception_once_then_reports_failure(tmp_path):
    tasks = [Task("campaign_tasks:raise_once", {"seed": 1}, extra={"marker_dir": str(tmp_path)}),
             Task("campaign_tasks:does_not_exist", {"seed": 2})] + _sum_tasks([3])
    recs = run_tasks(tasks, tmp_path / "store", retries=1)
    assert [r["status"] for r in recs] == ["ok", "failed", "ok"]
    assert [r["attempts"] for r in recs] == [2, 2, 1]
    assert "AttributeError" in recs[1]["error"]
    saved = json.loads(TaskStore(tmp_path / "store").path(tasks[1]).read_text())
    assert saved["status"] == "failed"


def test_episode_campaign_equals_serial(executor, tmp_path):
    """4 episodes (2 controllers × 2 seeds, 1 s each) on 2 workers: bit-identical metrics."""
    tasks = episode_tasks(["icr", "twist"], ["crab"], [0, 1], max_time=1.0, kicks=True, domain_randomization=0.2)
    serial = run_tasks(tasks, tmp_path / "serial")
    parallel = run_tasks(tasks, tmp_path / executor, executor=executor, workers=2)
    assert all(r["status"] == "ok" for r in serial + parallel)
    assert _metrics(parallel) == _metrics(serial)
    assert len({r["worker"] for r in parallel}) >= 1


def _batch_tasks(seeds, log_dir, group="g", **key):
    return [Task("campaign_tasks:seeded_sum_or_fail", {"seed": s, **key}, extra={"log_dir": str(log_dir)},
                 label=f"s{s}", batch="campaign_tasks:seeded_sum_batch", group=group) for s in seeds]


@pytest.mark.parametrize("executor_name", ["serial", "process"])
def test_batched_tasks_run_together_with_the_results_they_get_alone(executor_name, tmp_path):
    """Tasks of one batch group run in one call per worker; each gets its own record, equal to
    the task run alone; other groups and plain tasks run apart."""
    logs = tmp_path / "logs"
    logs.mkdir()
    tasks = _batch_tasks([1, 2, 3, 4], logs) + _batch_tasks([5, 6], logs, group="h") + _sum_tasks([7])
    workers = 1 if executor_name == "serial" else 2
    recs = run_tasks(tasks, tmp_path / "store", executor=executor_name, workers=workers)
    alone = run_tasks(_sum_tasks([1, 2, 3, 4, 5, 6, 7]), tmp_path / "alone")
    assert [r["result"] for r in recs] == [r["result"] for r in alone]
    batches = sorted(p.name for p in logs.glob("batch-*"))
    if executor_name == "serial":
        assert batches == ["batch-1-2-3-4", "batch-5-6"]
        assert [r["batch"] for r in recs[:6]] == [4, 4, 4, 4, 2, 2]
    else:  # one unit per worker: a unit of one task runs alone
        assert batches == ["batch-1-3", "batch-2-4"]
        assert [r.get("batch") for r in recs[:6]] == [2, 2, 2, 2, None, None]
    assert "batch" not in recs[6]


def test_a_failed_batch_is_run_again_task_by_task(tmp_path):
    """A batch that raises: each of its tasks runs again alone with the same attempt number (an
    isolation, not a retry: also with retries=0 and retry="transient"), so a bad episode does not
    sink the others."""
    logs = tmp_path / "logs"
    logs.mkdir()
    tasks = _batch_tasks([1, 2], logs, fail_batch=True)
    recs = run_tasks(tasks, tmp_path / "store", retries=1)
    assert [r["status"] for r in recs] == ["ok", "ok"] and [r["attempts"] for r in recs] == [1, 1]
    assert [r["result"] for r in recs] == [r["result"] for r in run_tasks(_sum_tasks([1, 2]), tmp_path / "alone")]
    for retry in ("any", "transient"):
        alone = run_tasks(tasks, tmp_path / f"store-{retry}", retries=0, retry=retry)
        assert [r["status"] for r in alone] == ["ok", "ok"] and [r["attempts"] for r in alone] == [1, 1]


def test_eval_batches_give_each_episode_its_metrics_alone_bit_for_bit(tmp_path):
    """azimut eval's episodes of one controller stepped as one vector env (episode_batch) give
    each the per-episode metrics of its episode run alone (episode_task): kicks, domain
    randomisation, a random track, scenarios, another robot."""
    from jobs.eval.campaign import episode_batch, episode_task

    cases = [episode_tasks(["icr", "twist"], ["crab", "random", "square"], [0, 3], max_time=3.0, kicks=True,
                           domain_randomization=0.2),
             episode_tasks(["twist"], ["hold", "reverse"], [1], max_time=3.0, robot="swerve")]
    for tasks in cases:
        for controller in {t.key["controller"] for t in tasks}:
            group = [t for t in tasks if t.key["controller"] == controller]
            batch = episode_batch([dict(t.key) for t in group], [dict(t.extra) for t in group])
            alone = [episode_task(**t.key, **t.extra) for t in group]
            assert [json.dumps(r["metrics"], sort_keys=True) for r in batch] == \
                   [json.dumps(r["metrics"], sort_keys=True) for r in alone]
    with pytest.raises(ValueError, match="differ only in track and seed"):
        mixed = episode_tasks(["icr", "twist"], ["crab"], [0])
        episode_batch([dict(t.key) for t in mixed], [{} for _ in mixed])


def test_a_killed_worker_is_retried_and_a_dead_task_does_not_sink_the_others(executor, tmp_path):
    tasks = ([Task("campaign_tasks:crash_once", {"seed": 1}, extra={"marker_dir": str(tmp_path)}),
              Task("campaign_tasks:crash_once", {"seed": 2, "always": True}, extra={"marker_dir": str(tmp_path)})]
             + _sum_tasks([3, 4, 5]))
    recs = run_tasks(tasks, tmp_path / "store", executor=executor, workers=2, retries=1)
    assert [r["status"] for r in recs] == ["ok", "failed", "ok", "ok", "ok"]
    assert recs[0]["attempts"] == 2 and recs[1]["attempts"] == 2
    assert all(r["attempts"] == 1 for r in recs[2:])
    assert "worker lost" in recs[1]["error"]
    serial = run_tasks(_sum_tasks([1]), tmp_path / "serial")
    assert recs[0]["result"] == serial[0]["result"]


def test_resume_after_an_interruption_recomputes_nothing_that_finished(executor, tmp_path):
    log = tmp_path / "log"
    log.mkdir()
    tasks = _sum_tasks(range(6), log_dir=str(log))
    store = tmp_path / "store"

    def stop_after_two(done, total, task, rec):
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(CampaignInterrupted):
        run_tasks(tasks, store, executor=executor, workers=2, progress=stop_after_two)
    finished = {p.name for p in store.glob("*.json")}
    assert len(finished) >= 2
    ran_before = {p.name: p.read_text().count("\n") for p in log.iterdir()}
    recs = run_tasks(tasks, store, executor=executor, workers=2, resume=True)
    for task in tasks:
        runs = (log / f"ran-{task.key['seed']}").read_text().count("\n")
        if f"{task.id}.json" in finished:  # saved before the interruption: not run again
            assert runs == ran_before[f"ran-{task.key['seed']}"]
    assert _results(recs) == _results(run_tasks(_sum_tasks(range(6)), tmp_path / "serial"))


def _results(records):
    return [json.dumps(r["result"], sort_keys=True) for r in records]


def test_a_run_without_resume_starts_afresh(tmp_path):
    log = tmp_path / "log"
    log.mkdir()
    tasks = _sum_tasks([0, 1], log_dir=str(log))
    run_tasks(tasks, tmp_path / "store")
    run_tasks(tasks, tmp_path / "store", resume=True)
    assert (log / "ran-0").read_text().count("\n") == 1
    run_tasks(tasks, tmp_path / "store")
    assert (log / "ran-0").read_text().count("\n") == 2


# ------------------------------------------------------------------------------------- CLI


def test_cli_eval_campaign_with_seeds_resume_and_report(tmp_path):
    out = tmp_path / "camp"
    argv = ["eval", "--tracks", "crab", "--controllers", "icr,twist", "--seeds", "0,1", "--max-time", "1",
            "--out", str(out)]
    assert main(argv + ["--workers", "2", "--executor", "process", "--no-plots"]) == 0
    data = json.loads((out / "metrics.json").read_text())
    assert [(r["controller"], r["seed"]) for r in data["episodes"]] == [("icr", 0), ("icr", 1), ("twist", 0),
                                                                        ("twist", 1)]
    cell = data["summary"][0]["metrics"]["rms_lateral_m"]
    assert cell["n"] == 2 and cell["lo"] <= cell["mean"] <= cell["hi"]
    first = {r["seed"]: r for r in data["episodes"]}
    assert main(argv + ["--resume"]) == 0  # serial, with plots: nothing recomputed, same rows
    data2 = json.loads((out / "metrics.json").read_text())
    assert data2["campaign"]["resumed"] == 4 and data2["campaign"]["computed"] == 0
    assert {r["seed"]: r for r in data2["episodes"]} == first
    report = (out / "report.md").read_text()
    assert report.index("## Summary") < report.index("| icr | crab | 2/0 |")


def test_cli_eval_plots_are_embedded_under_their_row(tmp_path):
    out = tmp_path / "camp"
    assert main(["eval", "--tracks", "crab", "--controllers", "icr,twist", "--seeds", "0", "--max-time", "1",
                 "--out", str(out)]) == 0
    report = (out / "report.md").read_text()
    for f in ("plots/compare_crab_trajectory.png", "plots/compare_crab_slip_force.png",
              "plots/icr_crab_trajectory.png", "plots/twist_crab_qua.png"):
        assert f"]({f})" in report and (out / f).stat().st_size > 1000
    assert report.index("#### icr on crab") < report.index("plots/icr_crab_trajectory.png") \
        < report.index("#### twist on crab") < report.index("plots/twist_crab_trajectory.png")


@pytest.mark.parametrize("flags", [["--seeds", "3-1"], ["--seeds", "x"], ["--workers", "0"], ["--max-time", "0"],
                                   ["--domain-randomization", "0.9"], ["--retries", "-1"],
                                   ["--ray-address", "auto", "--executor", "process"],
                                   ["--seed", "2", "--seeds", "0-1"], ["--executor", "dask"], ["--bootstrap", "5"]])
def test_cli_eval_refuses_bad_campaign_flags(flags, tmp_path, capsys):
    assert main(["eval", "--out", str(tmp_path / "x")] + flags) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error" in err[0]
    assert not (tmp_path / "x").exists()


def test_kick_study_on_workers_equals_the_serial_study(tmp_path):
    from dataclasses import asdict

    from jobs.eval.robustness import kick_study, kick_study_campaign

    serial = kick_study(2, "icr", seed0=1003)
    parallel = kick_study_campaign(2, "icr", seed0=1003, store=tmp_path / "kicks", executor="process", workers=2)
    assert [json.dumps(asdict(t)) for t in parallel] == [json.dumps(asdict(t)) for t in serial]


def test_auto_executor_is_processes_on_one_machine_and_ray_with_an_address():
    from jobs.campaign.engine import ray_available, resolve_executor
    assert resolve_executor("auto", 1, None) == "serial"
    assert resolve_executor("auto", 2, None) == "process"  # faster than a local Ray instance here
    if ray_available():
        assert resolve_executor("auto", 2, "auto") == "ray"


def test_a_new_eval_removes_only_what_eval_wrote(tmp_path):
    """Without --resume, azimut eval clears its own records and plots from OUT, and leaves every
    other file there (a user's figure.png and data.json were deleted)."""
    out = tmp_path / "out"
    (out / "plots").mkdir(parents=True)
    (out / "episodes").mkdir()
    mine = [out / "plots" / "figure.png", out / "episodes" / "data.json", out / "episodes" / "notes-0123456789ab.json"]
    for p in mine:
        p.write_text(json.dumps({"id": "not-this-file"}))
    argv = ["eval", "--controllers", "twist", "--tracks", "crab", "--max-time", "0.3", "--out", str(out)]
    assert main(argv) == 0
    written = sorted(p.name for p in (out / "plots").glob("*.png") if p.name != "figure.png")
    records = sorted(p.name for p in (out / "episodes").iterdir() if p not in mine)
    assert written and records
    stale = out / "plots" / "old_crab_trajectory.png"  # named as eval names its plots: a previous run's
    stale.write_bytes(b"")
    assert main(argv) == 0
    assert all(p.is_file() for p in mine) and not stale.exists()
    assert sorted(p.name for p in (out / "episodes").iterdir() if p not in mine) == records
