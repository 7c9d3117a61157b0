"""Diagnosis benchmark: issue 10's seeded suite (detection, false alarms, held-out/floor) and timing.

The suite's cases come from `server.diagnose_suite` (effects of every kind, two at once, out of
the vocabulary, on harder campaigns), then clean campaigns for the false-alarm rate; they run in a
process pool with a progress line per case on stderr. The time per campaign is measured apart,
one campaign at a time, at each size asked (100 and 1,000 poses by default).
"""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np

from .diagnose_suite import KINDS, draw_case, run_case, suite, summarize

TARGET_S = {100: 10.0, 1000: 60.0}  # issue 10: seconds per campaign on 2 cores
CLEAN_SEED0 = 100_000  # clean campaigns draw from seeds apart from the effect cases'
FULL = {"effect_cases": 60, "clean_cases": 200}
QUICK = {"effect_cases": 10, "clean_cases": 10}
TIMED_EFFECT = "joint_compliance:2=0.3"


def _case(seed_kind):
    seed, kind = seed_kind
    t0 = time.perf_counter()
    r = run_case(draw_case(seed, kind))
    r["wall_seconds"] = time.perf_counter() - t0
    return r


def _line(r) -> str:
    c = r["case"]
    head = f"{c['kind']} seed {c['seed']}"
    if "skipped" in r:
        return f"{head}: skipped ({r['skipped']})"
    named = ", ".join(":".join(str(v) for v in n if v is not None) for n in r["named"]) or "nothing"
    ratio = f", held-out/floor {r['ratio']:.2f}" if r["ratio"] is not None else ""
    return (
        f"{head}: {c['poses']} poses, {', '.join(c['effects']) or 'clean'}; named {named}"
        f"{ratio} ({r['wall_seconds']:.1f} s)"
    )


def run_suite(pairs, workers: int = 2, log=None) -> list[dict]:
    """Run (seed, kind) cases, in a pool when workers > 1; results in the pairs' order."""
    results: list = [None] * len(pairs)  # filled in as the cases finish, in any order
    done = 0

    def report(i, r):
        nonlocal done
        done += 1
        results[i] = r
        if log:
            log(f"[bench] {done}/{len(pairs)} {_line(r)}")

    if workers <= 1:
        for i, p in enumerate(pairs):
            report(i, _case(p))
        return results
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(_case, p): i for i, p in enumerate(pairs)}
        for f in as_completed(futures):
            report(futures[f], f.result())
    return results


def time_campaign(poses: int, seed: int = 0) -> dict:
    """Wall time of one diagnosis of a campaign of that size (the IRB 2600, one hidden effect)."""
    from robocal.drivers.cell import VirtualCell
    from robocal.drivers.effects import make_effects
    from robocal.solver.diagnose import diagnose

    from .formats.cell_json import default_cell

    cell = default_cell()
    vc = VirtualCell.random(cell.robot, cell.targets, seed=seed)
    vc.effects.extend(make_effects([TIMED_EFFECT], vc, seed))
    meas = vc.campaign(poses, seed=seed)
    targets = np.array([cell.targets[t] for t in meas.target_names])
    t0, c0 = time.perf_counter(), time.process_time()
    d = diagnose(cell.robot, targets, meas.target_names, meas.q, meas.xyz, meas.time_s, meas.temp_c)
    wall = time.perf_counter() - t0
    target = TARGET_S.get(poses)
    return {
        "poses": poses,
        "effect": TIMED_EFFECT,
        "seconds": wall,
        "cpu_seconds": time.process_time() - c0,
        "stages_seconds": d.report["seconds"],
        "fits": d.report["cross_validation"]["fits"],
        "effects_named": [
            e["name"] + (f":{e['joint']}" if "joint" in e else "") for e in d.report["effects"]
        ],
        "target_seconds": target,
        "met": None if target is None else wall <= target,
    }


def run_diagnose_bench(
    quick: bool = False,
    effect_cases: int | None = None,
    clean_cases: int | None = None,
    sizes=(100, 1000),
    workers: int = 2,
    seed: int = 0,
) -> dict:
    """The suite's figures (detection per effect and size, false alarms, held-out/floor) and timing."""
    counts = dict(QUICK if quick else FULL)
    if effect_cases is not None:
        counts["effect_cases"] = effect_cases
    if clean_cases is not None:
        counts["clean_cases"] = clean_cases
    effect_kinds = tuple(k for k in KINDS if k != "clean")
    pairs = suite(range(seed, seed + counts["effect_cases"]), effect_kinds)
    pairs += [(CLEAN_SEED0 + seed + i, "clean") for i in range(counts["clean_cases"])]

    def log(line):
        print(line, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    results = run_suite(pairs, workers, log)
    suite_s = time.perf_counter() - t0
    timing = {}
    for poses in sizes:
        log(f"[bench] timing one diagnosis at {poses} poses")
        timing[str(poses)] = time_campaign(poses, seed)
    summary = summarize(results)
    return {
        "benchmark": "diagnose",
        "quick": quick,
        "seed": seed,
        "workers": workers,
        "cpu_count": os.cpu_count(),
        **counts,
        "suite_seconds": suite_s,
        "summary": summary,
        "timing": timing,
        "met": {
            "detection_rate_min_0.9": _at_least(summary["detection"]["rate"], 0.9),
            "false_alarm_rate_max_0.01": _at_most(summary["false_alarms"]["rate"], 0.01),
            "holdout_over_floor_median_max_1.2": _at_most(
                summary["holdout_over_floor"]["median"], 1.2
            ),
            "outlier_cases_median_max_1.5": _at_most(
                summary["holdout_over_floor_outlier_cases"]["median"], 1.5
            ),
            "out_of_vocabulary_named_only_if_it_pays": (
                None
                if not summary["out_of_vocabulary"]["cases"]
                else summary["out_of_vocabulary"]["named_without_payoff"] == 0
            ),
            **{f"seconds_{k}_poses": v["met"] for k, v in timing.items()},
        },
        "cases": results,
    }


def _at_least(v, bound):
    return None if v is None else v >= bound


def _at_most(v, bound):
    return None if v is None else v <= bound
