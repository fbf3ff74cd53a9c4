"""Every figure on a results page and in README.md's table is the one its JSON holds: the
tables are read back from the built site and each cell compared with the JSON."""

import json
import math
import re
from html.parser import HTMLParser

from tests.helpers import REPOSITORY

RESULTS = REPOSITORY / "docs" / "results"


class _Tables(HTMLParser):
    """Every table of a page: its rows, as lists of cell texts."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[list[list[str]]] = []
        self.cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self.cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self.cell is not None:
            self.tables[-1][-1].append("".join(self.cell).strip())
            self.cell = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell.append(data)


def _rows(page, *header: str) -> dict[str, list[str]]:
    """The rows of the table of `page` whose header row starts with `header`, by first cell."""
    parser = _Tables()
    parser.feed(page.read_text())
    table = next(t for t in parser.tables if tuple(t[0][:len(header)]) == header)
    return {row[0]: row[1:] for row in table[1:]}


def _numbers(cell: str) -> list[float]:
    return [float(n) for n in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", cell)]


def _close(shown: float, value: float) -> bool:
    """`shown` is `value` to the three significant figures the pages print."""
    return math.isclose(shown, value, rel_tol=5e-3)


def test_the_thesis_page_shows_the_summary(site):
    summary = json.loads((RESULTS / "demo" / "summary.json").read_text())
    page = site / "results" / "thesis" / "index.html"
    rows = _rows(page, "scenario")
    names = {"PID alone": "pid", "rigid-body FF": "rigid-body", "LSTM": "lstm",
             "identified rigid-body FF": "identified", "CNN-LSTM": "cnn-lstm", "TCN": "tcn",
             "physics-guided": "pgnn", "ILC limit": "limit"}
    checked = 0
    for name, key in names.items():
        s = summary["scenarios"][key]
        e2, e2_ratio, einf_ratio, per_limit = (_numbers(c) for c in rows[name][:4])
        for shown, metric in ((e2, "e2"), (e2_ratio, "e2_ratio"), (einf_ratio, "einf_ratio"),
                              (per_limit, "e2_per_limit")):
            assert all(_close(v, s[a][metric]) for v, a in zip(shown, "xy")), (name, metric)
            checked += 2
    assert checked == 64
    training = _rows(page, "model")
    for name, key in names.items():
        if key in summary["training"]:
            t = summary["training"][key]
            seconds, epochs, parameters, mse = training[name]
            assert _close(float(seconds), t["seconds"]) and _close(float(mse), t["test_mse"])
            assert epochs == f"{t['epochs']} ({t['best_epoch']})"
            assert parameters == str(t["parameters"])
    held = _rows(page, "scenario", "geometric mean x / y")
    for key, ratios in summary["held_out"]["e2_ratio"].items():
        name = next(n for n, k in names.items() if k == key)
        mean, worst = (_numbers(c) for c in held[name])
        for a, shown_mean, shown_worst in zip("xy", mean, worst):
            assert _close(shown_mean, math.exp(sum(map(math.log, ratios[a])) / len(ratios[a])))
            assert _close(shown_worst, min(ratios[a]))
    own = "Own share over the noise floor" in page.read_text()
    assert own == ("noise_floor" in summary)  # the sim demo's encoders are exact: no floor


def test_the_thesis_page_gives_the_own_share_over_a_floor():
    """A demo summary with a noise floor (evaluate's summarize: the limit at the floor in x,
    over it in y) puts each scenario's own share on the page, beside its e2 and ratio, under
    the floor it was computed against."""
    import gen_results

    from flexff.learning.report import summarize

    stored, stamp = gen_results.load("demo")
    metrics = {name: {a: {n: s[a][n] for n in ("e2", "einf", "rms")} for a in "xy"}
               for name, s in stored["scenarios"].items()}
    limit = metrics["limit"]
    floor = {"x": 1.5 * limit["x"]["e2"], "y": 0.5 * limit["y"]["e2"]}
    summary = {**stored, "scenarios": summarize(metrics, floor), "noise_floor": floor}
    page = gen_results.demo_page(summary, stamp)
    assert "\n".join(gen_results.own_share_markdown(summary)) in page
    head = next(line for line in page.splitlines() if "own share x / y" in line)
    assert _numbers(head.split("floor")[1]) == [float(gen_results.figure(floor[a]))
                                                for a in "xy"]
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
            for line in page.split(head)[1].split("\n\n")[0].splitlines()[2:]}
    assert rows["ILC limit"][2].startswith("at the floor / ")
    for key, s in summary["scenarios"].items():
        e2, ratio, own = rows[gen_results.SCENARIOS[key]]
        assert all(map(_close, _numbers(e2), (s[a]["e2"] for a in "xy"))), key
        assert all(map(_close, _numbers(ratio), (s[a]["e2_ratio"] for a in "xy"))), key
        shares = [s[a]["own_e2"] for a in "xy" if not s[a]["at_floor"]]
        assert shares and all(map(_close, _numbers(own), shares)), key
        assert all(math.isclose(s[a]["own_e2"]**2 + floor[a]**2, s[a]["e2"]**2, rel_tol=1e-9)
                   for a in "xy" if not s[a]["at_floor"])



def test_the_benchmarks_page_shows_the_bench(site):
    bench = json.loads((RESULTS / "bench" / "bench.json").read_text())
    page = site / "results" / "benchmarks" / "index.html"
    rows = _rows(page, "plant")
    for variant, p in bench["plant_step"].items():
        shown = [_numbers(c)[0] for c in rows[variant]]
        assert all(_close(v, p[k]) for v, k in zip(shown, (
            "master_us_per_step", "isolated_us_per_step", "python_us_per_step",
            "c_us_per_step"))), variant
    loop = bench["closed_loop"]
    rows = _rows(page, "engine")
    import gen_results

    for engine, us in loop["us_per_step"].items():
        shown = [_numbers(c)[0] for c in rows[gen_results.ENGINES.get(engine, engine)]]
        assert _close(shown[0], us) and _close(shown[1], loop["real_time_factor"][engine])
    rows = _rows(page, "feedforward")
    for name, f in bench["learned_feedforward"].items():
        if isinstance(f, dict):
            shown = [_numbers(c)[0] for c in rows[name]]
            assert _close(shown[0], f["us_per_step"]), name
            assert _close(shown[1], f["ratio_over_without_feedforward"]), name
    network = bench["network_call"]
    rows = _rows(page, "model", "generated C: p50 / p99 [µs]")
    assert set(rows) == {gen_results.SCENARIOS[kind] for kind in network["models"]}
    for kind, model in network["models"].items():
        c_times, ort_times, c_size, ort_size, ratios = rows[gen_results.SCENARIOS[kind]]
        for shown, figures, unit in ((c_times, model["c"], "_us"),
                                     (ort_times, model["onnxruntime"], "_us"),
                                     (ratios, model["ratio_c_over_onnxruntime"], "")):
            p50, p99 = _numbers(shown)
            assert _close(p50, figures[f"p50{unit}"]) and _close(p99, figures[f"p99{unit}"]), kind
        assert _close(float(c_size), model["c"]["fmu_bytes"] / 1e6), kind
        assert _close(float(ort_size), model["onnxruntime"]["fmu_bytes"] / 1e6), kind
    rows = _rows(page, "loop")
    for name in ("tcn", "lstm", "idle"):
        r = bench["realtime"][name]
        base = r["tasks"]["base"] if "tasks" in r else r
        tet = _numbers(rows[name][0])
        assert all(map(_close, tet, (base["tet_us"][q] for q in ("p50", "p99", "max")))), name
        assert int(rows[name][1]) == r["overruns"], name


def test_pages_are_stamped(site):
    machines = [("machines", f"machines/{f.name}") for f in (RESULTS / "machines").iterdir()]
    for page, kind in (("thesis", "demo"), ("benchmarks", "bench"), ("benchmarks", "processes"),
                       ("benchmarks", "training"), *machines):
        stamp = json.loads((RESULTS / kind / "stamp.json").read_text())
        text = (site / "results" / page / "index.html").read_text()
        assert stamp["commit"][:10] in text and stamp["date"] in text, page


def test_the_readme_table_is_generated_from_the_summary():
    import gen_results

    summary = json.loads((RESULTS / "demo" / "summary.json").read_text())
    readme = (REPOSITORY / "README.md").read_text()
    assert f"{gen_results.README_START}\n{gen_results.readme_table(summary)}\n" \
           f"{gen_results.README_END}" in readme
    flexff_row = next(line for line in readme.splitlines() if line.startswith("| flexff"))
    shown = _numbers(flexff_row.split("|", 2)[2])
    expected = [summary["scenarios"][m][a]["e2_ratio"] for m in gen_results.MODELS for a in "xy"]
    assert len(shown) == len(expected) and all(map(_close, shown, expected))


def test_the_readme_machines_table_is_generated_from_the_summaries():
    import gen_results

    readme = (REPOSITORY / "README.md").read_text()
    table = gen_results.readme_machines_table()
    assert f"{gen_results.README_MACHINES}\n{table}\n{gen_results.README_END}" in readme
    for folder in ("drive", "stage"):
        summary = json.loads((RESULTS / "machines" / folder / "summary.json").read_text())
        for axis in summary["axes"]:
            row = next(line for line in table.splitlines()
                       if f"flexff/machines/examples/{folder}.toml`, {axis} |" in line)
            shown = _numbers(row.split("|", 2)[2])
            expected = [s[axis]["e2_ratio"] for name, s in summary["scenarios"].items()
                        if name != "pid"]
            assert len(shown) == len(expected) and all(map(_close, shown, expected))


def test_the_benchmarks_page_shows_the_processes(site):
    import gen_results

    bench = json.loads((RESULTS / "processes" / "bench.json").read_text())
    page = site / "results" / "benchmarks" / "index.html"
    parser = _Tables()
    parser.feed(page.read_text())
    table = next(t for t in parser.tables if t[0][:2] == ["steps", "tool"])
    shown = {(row[0], row[1]): row[2:] for row in table[1:]}
    for key, runs in bench.items():
        if key.endswith("_steps"):
            for tool in ("flexff", "fmpy"):
                wall, peak, _ = shown[key.removesuffix("_steps"), tool]
                assert _close(float(wall), runs[tool]["wall_s"]), (key, tool)
                assert _close(float(peak), runs[tool]["peak_mib"]), (key, tool)
            assert _close(float(shown[key.removesuffix("_steps"), "fmpy"][2]),
                          runs["speedup_vs_fmpy"])
    startup = _rows(page, "process")
    for name, r in bench["startup"].items():
        assert _close(float(startup[name][0]), r["wall_s"]), name
    isolation = _rows(page, "variant")
    for key, label in gen_results.ISOLATION:
        if f"{key}_us_per_step" in bench["isolation"]:
            assert _close(float(isolation[label][0]), bench["isolation"][f"{key}_us_per_step"])


def test_the_machines_page_shows_each_evaluation(site):
    """Every example machine's table: e2 ratios of a loop's evaluation, relative force errors
    of a logs' evaluation, and the identified parameters, each as its summary.json holds."""
    parser = _Tables()
    parser.feed((site / "results" / "machines" / "index.html").read_text())
    folders = sorted((RESULTS / "machines").iterdir())
    assert folders
    tables = iter(parser.tables)
    for folder in folders:
        summary = json.loads((folder / "summary.json").read_text())
        scores, identified = next(tables), next(tables)
        key, scale = ("e2_ratio", 1) if "scenarios" in summary else (None, 100)
        by_scenario = summary.get("scenarios") or summary["relative_error"]
        floors = summary.get("noise_floor", {})
        assert len(scores) == 1 + len(summary["axes"]) + len(floors)
        for row in scores[1:]:
            axis, _, floor = row[0].partition(": e2 / noise floor (")
            for name, cell in zip(by_scenario, row[1:]):
                value = by_scenario[name][axis]
                if floor:  # a row of each run's e2 over the axis's noise floor
                    assert _close(float(floor.rstrip(")")), floors[axis])
                    value = value["e2"] / floors[axis]
                else:
                    value = scale * (value[key] if key else value)
                assert _close(float(cell), value), (folder.name, name, row[0])
        rows = [(axis, term, value, std) for axis, fit in summary["identified"].items()
                for term, value, std in zip(fit["terms"], fit["parameters"], fit["std"])]
        assert len(identified) == len(rows) + 1
        for (axis, term, value, std), row in zip(rows, identified[1:]):
            assert row[:2] == [axis, term]
            assert _close(float(row[2]), value) and _close(float(row[3]), std)


def test_the_benchmarks_page_shows_the_trainings(site):
    bench = json.loads((RESULTS / "training" / "bench.json").read_text())
    parser = _Tables()
    parser.feed((site / "results" / "benchmarks" / "index.html").read_text())
    tables = [t for t in parser.tables if t[0][:3] == ["model", "epochs", "CPU [s/epoch]"]]
    assert len(tables) == len(bench["presets"])
    for table, entries in zip(tables, bench["presets"].values()):
        rows = {row[0]: row[1:] for row in table[1:]}
        assert set(rows) == set(entries)
        for kind, entry in entries.items():
            epochs, cpu, cuda, speedup = rows[kind][:4]
            assert int(epochs) == entry["epochs"]
            for shown, device in ((cpu, "cpu"), (cuda, "cuda")):
                value = entry.get(device, {}).get("epoch_s")
                assert shown == "–" if value is None else _close(float(shown), value), kind
            assert speedup == "–" if "speedup" not in entry else \
                _close(float(speedup), entry["speedup"])

