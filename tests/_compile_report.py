"""Where the test suite's time goes: per test, wall time against JAX's tracing, lowering and
XLA compilation (`jax.monitoring` duration events), written as JSON when pytest runs with
``--jax-time-report=PATH`` (one JSON line per test, appended as each test ends so that a run
cut short keeps what it measured, one file per pytest-xdist worker, ``PATH.<worker>.jsonl``;
merge and rank them with ``python tests/_compile_report.py PATH``). Compilation served by the
persistent cache emits no backend-compile event, so the report counts only the programs the
run really compiled. Loaded by tests/conftest.py; off unless the option is given."""

from __future__ import annotations

import collections
import glob
import json
import os
import sys
import time

import pytest

EVENTS = {"/jax/core/compile/jaxpr_trace_duration": "trace",
          "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
          "/jax/core/compile/backend_compile_duration": "compile"}


class TimeReport:
    """pytest plugin: accumulates the JAX events of each test phase (setup + call +
    teardown) into one row per test."""

    def __init__(self, path: str):
        import jax.monitoring

        self.path = path
        self.totals = collections.defaultdict(float)
        self.programs = []  # (function name, XLA compile s) of the programs compiled so far
        self.rows = {}
        self.out = None
        jax.monitoring.register_event_duration_secs_listener(self._event)

    def _event(self, event, duration, fun_name="?", **_):
        if event in EVENTS:
            self.totals[EVENTS[event]] += duration
            if EVENTS[event] == "compile":
                self.programs.append((str(fun_name), duration))

    def _phase(self, item):
        before, t0, n = dict(self.totals), time.perf_counter(), len(self.programs)
        yield
        row = self.rows.setdefault(item.nodeid, {"wall": 0.0, **{k: 0.0 for k in EVENTS.values()},
                                                 "programs": []})
        row["wall"] += time.perf_counter() - t0
        row["programs"] += [[f, round(s, 3)] for f, s in self.programs[n:]]
        for k in EVENTS.values():
            row[k] += self.totals[k] - before.get(k, 0.0)

    def pytest_runtest_logfinish(self, nodeid, location):
        if nodeid not in self.rows:
            return
        if self.out is None:
            worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
            self.out = open(f"{self.path}.{worker}.jsonl", "a", buffering=1)
        self.out.write(json.dumps({"test": nodeid, **self.rows.pop(nodeid)}) + "\n")

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_setup(self, item):
        yield from self._phase(item)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_call(self, item):
        yield from self._phase(item)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_teardown(self, item):
        yield from self._phase(item)

    def pytest_unconfigure(self, config):
        if self.out is not None:
            self.out.close()


def summary(path: str, top: int = 30) -> str:
    """The merged report: totals, per file, and the `top` tests by wall time."""
    rows = {}
    for name in glob.glob(f"{path}.*.jsonl"):
        with open(name) as f:
            for line in f:
                r = json.loads(line)
                rows[r.pop("test")] = r
    keys = ("wall", *EVENTS.values())
    total = {k: sum(r[k] for r in rows.values()) for k in keys}
    per_file = collections.defaultdict(lambda: dict.fromkeys(keys, 0.0))
    for nodeid, r in rows.items():
        for k in keys:
            per_file[nodeid.split("::")[0]][k] += r[k]

    def line(name, r):
        rest = r["wall"] - r["trace"] - r["lower"] - r["compile"]
        return (f"| {name} | {r['wall']:.1f} | {r['trace']:.1f} | {r['lower']:.1f} "
                f"| {r['compile']:.1f} | {rest:.1f} |")

    head = ["| | wall s | trace s | lower s | XLA compile s | the rest s |", "|---|---:|---:|---:|---:|---:|"]
    out = [f"{len(rows)} tests (worker-seconds, summed over workers)", "", *head,
           line("all", total), "", "Per file:", "", *head]
    out += [line(f, r) for f, r in sorted(per_file.items(), key=lambda kv: -kv[1]["wall"])]
    out += ["", f"The {top} longest tests:", "", *head]
    out += [line(n, r) for n, r in sorted(rows.items(), key=lambda kv: -kv[1]["wall"])[:top]]
    # the programs by name: how often the run compiled a program of that name, and for how long
    # (a name compiled many times is a candidate for one shared callable or fixed shapes)
    programs = collections.defaultdict(lambda: [0, 0.0, set()])
    for nodeid, r in rows.items():
        for name, s in r.get("programs", ()):
            p = programs[name]
            p[0], p[1] = p[0] + 1, p[1] + s
            p[2].add(nodeid.split("::")[0])
    out += ["", f"The {top} programs with the most XLA compile time:", "",
            "| program | compiles | XLA compile s | files |", "|---|---:|---:|---|"]
    out += [f"| {n} | {c} | {s:.1f} | {len(files)} |"
            for n, (c, s, files) in sorted(programs.items(), key=lambda kv: -kv[1][1])[:top]]
    return "\n".join(out)


if __name__ == "__main__":
    print(summary(sys.argv[1], *(int(a) for a in sys.argv[2:3])))
