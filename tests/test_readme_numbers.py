"""Every number the documentation quotes from a committed artifact (``figures/*``) agrees with it.

The checked document is the concatenation of the docs pages that quote measured numbers
(`PAGES`, the study pages of the site; the README is short and links to them). Below,
"README" means that document. The contract between it and the artifacts:

* A README table that quotes measured numbers says where they come from in its caption (the
  paragraph above it names ``figures/<file>``), and this module holds one entry per such
  table in `SPECS`: the table (found by a unique piece of its header line), the artifact
  files (JSON where the study writes one; the ``.md`` files are renderings of them), and a
  function from the artifacts to the expected rows. A row is found by its label cells (the
  first `key_cols` cells, exact text); each other cell is either not checked (None) or holds
  the listed numbers in order (a cell such as ``4.2 / 0.87 / 0.082`` is three numbers).
  README rows without an artifact row, and artifact rows missing from the README, are
  mismatches too.
* A table that copies an artifact table whole (`Verbatim`) must equal the study's own
  rendering of the artifact's JSON.
* Numbers in running text are `Sentence` entries: a regular expression (spaces match any
  white space, so a sentence may wrap) whose groups are the checked numbers, or the words
  met / missed of a target (`Verdict`).
* Prose that is only true of the present artifacts ("that run predates …") is a `Claim`: the
  README must contain it exactly while its condition on the artifacts holds.
* A number is compared at the precision the README prints it: ``9.18`` with 0.005,
  ``16,600`` with 50 (trailing zeros of a thousands-separated integer are not significant),
  ``5.7e3`` with 50, ``2.1·10⁶`` with 5·10⁴, a bare ``0`` exactly.
* `test_every_artifact_table_is_checked` fails when a table whose caption names a
  ``figures/`` file has no entry here (or in `NOT_CHECKED`, with the reason).

From the command line (run from the repository root; the package must be importable)::

    PYTHONPATH=. python tests/test_readme_numbers.py          # list every mismatch
    PYTHONPATH=. python tests/test_readme_numbers.py --fix    # rewrite the pages' numbers

``--fix`` rewrites each mismatching number in the README's own style and precision, flips
met / missed, and replaces verbatim tables; rows that exist on one side only, patterns that
no longer match and claims that no longer hold are listed for a person to edit. Run it after regenerating the
benchmarks, read the diff, and check the prose around the numbers still says what they say.
"""

from __future__ import annotations

import json
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
FIGURES = ROOT / "figures"
#: the docs pages that quote artifacts' numbers (checked as one document)
PAGES = ("studies/figure7.md", "studies/ibl.md", "studies/improved.md",
         "studies/classic-models.md", "theory/accuracy.md", "studies/fitting.md",
         "studies/error-runtime.md", "studies/performance.md", "how-to/devices.md",
         "studies/scaling.md", "getting-started/conventions.md", "studies/photographs.md",
         "getting-started/methods.md")
_MARK = re.compile(r"\n\n<!-- page: (\S+) -->\n\n")


def read_document() -> str:
    """The pages in `PAGES` as one text, each after a marker that `write_document` splits on."""
    return "".join(f"\n\n<!-- page: {p} -->\n\n" + (DOCS / p).read_text(encoding="utf-8")
                   for p in PAGES)


def write_document(text: str) -> None:
    parts = _MARK.split(text)
    for name, body in zip(parts[1::2], parts[2::2]):
        (DOCS / name).write_text(body, encoding="utf-8")

# ------------------------------------------------------------------------------- numbers

_SUP = str.maketrans("⁰¹²³⁴⁵⁶⁷⁸⁹⁻", "0123456789-")
_TO_SUP = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")
NUM_RE = re.compile(
    r"(?<![\w.·/^])(?P<sign>−|(?<![^\s(|])-)?(?P<int>\d{1,3}(?:,\d{3})+|\d+)(?:\.(?P<frac>\d+))?"
    r"(?:e(?P<exp>[+-]?\d+)|·10(?P<sup>[⁻]?[⁰¹²³⁴⁵⁶⁷⁸⁹]+))?(?![\w²³⁴⁵⁶⁷⁸⁹⁰¹])(?!\.\d)")


@dataclass(frozen=True)
class Token:
    """One printed number: its text, value and the unit of its last printed digit."""

    text: str
    value: float
    unit: float  # 0: exact

    @classmethod
    def parse(cls, text: str) -> Token:
        m = NUM_RE.fullmatch(text)
        if m is None:
            raise ValueError(f"not a number token: {text!r}")
        digits, frac = m["int"].replace(",", ""), m["frac"] or ""
        exp = int(m["exp"]) if m["exp"] else (int(m["sup"].translate(_SUP)) if m["sup"] else 0)
        value = float(f"{digits}.{frac or 0}") * 10.0**exp * (-1 if m["sign"] else 1)
        if frac:
            unit = 10.0 ** (exp - len(frac))
        elif m["exp"] or m["sup"]:
            unit = 10.0**exp
        elif "," in m["int"]:
            unit = 10.0 ** (len(digits) - len(digits.rstrip("0")))
        else:
            unit = 0.0 if value == 0 else 1.0
        return cls(text, value, unit)

    def agrees(self, v: float) -> bool:
        if v is None or not math.isfinite(v):
            return False
        if self.unit == 0:
            return v == 0
        return abs(self.value - v) <= 0.5 * self.unit * (1 + 1e-9) + 1e-300

    def like(self, v: float) -> str:
        """`v` printed in this token's style and precision."""
        m = NUM_RE.fullmatch(self.text)
        sign = ("−" if m["sign"] in (None, "−") else "-") if v < 0 else ""
        a = abs(v)
        frac = m["frac"] or ""
        if m["exp"] or m["sup"]:
            e = 0 if a == 0 else math.floor(math.log10(a))
            mant = round(a / 10.0**e, len(frac))
            if mant >= 10:
                e, mant = e + 1, mant / 10
            ms = f"{mant:.{len(frac)}f}"
            if m["sup"]:
                return f"{sign}{ms}·10{str(e).translate(_TO_SUP)}"
            digits = m["exp"].lstrip("+-")
            python_style = m["exp"].startswith("+") or (len(digits) == 2 and digits[0] == "0")
            es = f"{e:+03d}" if python_style else str(e)
            return f"{sign}{ms}e{es}"
        if frac:
            if m["int"] == "0" and a != 0:  # 0.0019: keep the significant digits
                sig = len(frac.lstrip("0"))
                dec = max(sig - 1 - math.floor(math.log10(a)), 0)
            else:
                dec = len(frac)
            return f"{sign}{a:.{dec}f}"
        if "," in m["int"]:
            digits = m["int"].replace(",", "")
            sig = max(len(digits.rstrip("0")), 1)
            e = math.floor(math.log10(a)) if a else 0
            r = round(a, sig - 1 - e)
            return f"{sign}{int(r):,}"
        return f"{sign}{a:.0f}"


@dataclass(frozen=True)
class Verdict:
    """A target's verdict: README word "met" (True) or "missed" (False)."""

    met: bool

    @property
    def word(self) -> str:
        return "met" if self.met else "missed"


@dataclass
class Mismatch:
    where: str
    readme: str
    artifact: Any
    span: tuple[int, int] | None = None  # README character span to replace
    replacement: str | None = None

    def __str__(self) -> str:
        fix = f" -> {self.replacement!r}" if self.replacement is not None else " (edit by hand)"
        return f"{self.where}: README {self.readme!r}, artifact {self.artifact!r}{fix}"


def _compare(expected, text: str, offset: int, where: str, out: list[Mismatch]) -> None:
    """Compare one README fragment (`text` at `offset`) with its expected numbers."""
    if expected is None:
        return
    exp = expected if isinstance(expected, list) else [expected]
    toks = [(m.group(0), m.start()) for m in NUM_RE.finditer(text)]
    if len(toks) != len(exp):
        out.append(Mismatch(where, text.strip(), exp))
        return
    for (s, i), e in zip(toks, exp):
        if e is None:
            continue
        t = Token.parse(s)
        if not t.agrees(float(e)):
            out.append(Mismatch(where, s, e, (offset + i, offset + i + len(s)), t.like(float(e))))


# ------------------------------------------------------------------------------ README parsing

_PIPE = re.compile(r"(?<!\\)\|")


@dataclass
class MdTable:
    start: int  # character offset of the header line
    end: int  # character offset just past the last row's newline
    header: str
    rows: list[list[tuple[str, int]]]  # per row: (cell text, character offset)
    caption: str

    def key(self, row, n: int) -> tuple[str, ...]:
        return tuple(c.strip() for c, _ in row[:n])


def _cells(line: str, offset: int) -> list[tuple[str, int]]:
    bars = [m.start() for m in _PIPE.finditer(line)]
    return [(line[a + 1:b], offset + a + 1) for a, b in zip(bars, bars[1:])]


def md_tables(text: str) -> list[MdTable]:
    """Every markdown table of `text`, with its caption: the last paragraph above it that is
    not a table (a table right under another shares its caption)."""
    lines = text.splitlines(keepends=True)
    offs = [0]
    for ln in lines:
        offs.append(offs[-1] + len(ln))
    tables, i, caption = [], 0, ""
    para: list[str] = []
    in_code = False
    while i < len(lines):
        s = lines[i].strip()
        if s.startswith("```"):
            in_code = not in_code
        if not in_code and s.startswith("|") and i + 1 < len(lines) \
                and re.match(r"^\|(\s*:?-+:?\s*\|)+\s*$", lines[i + 1].strip()):
            if para:
                caption = " ".join(para)
            j = i + 2
            rows = []
            while j < len(lines) and lines[j].strip().startswith("|"):
                rows.append(_cells(lines[j].rstrip("\n"), offs[j]))
                j += 1
            tables.append(MdTable(offs[i], offs[j], s, rows, caption))
            para, i = [], j
            continue
        if s and not s.startswith("#"):
            para.append(s)
        elif not s and para:
            caption, para = " ".join(para), []
        elif s.startswith("#"):
            para, caption = [], ""
        i += 1
    return tables


def _find_table(tables, anchor: str) -> MdTable | None:
    hits = [t for t in tables if anchor in t.header]
    return hits[0] if len(hits) == 1 else None


# ------------------------------------------------------------------------------ specs

_cache: dict[str, Any] = {}


def artifact(name: str):
    """``figures/<name>``: parsed JSON, or text for other files (read once)."""
    if name not in _cache:
        text = (FIGURES / name).read_text(encoding="utf-8")
        _cache[name] = json.loads(text) if name.endswith(".json") else text
    return _cache[name]


@dataclass
class Table:
    """A README table whose numbers come from `sources` via `rows` (module docstring)."""

    anchor: str
    sources: tuple[str, ...]
    key_cols: int
    rows: Callable[[], dict]

    def check(self, text: str, tables: list[MdTable]) -> list[Mismatch]:
        t = _find_table(tables, self.anchor)
        if t is None:
            return [Mismatch(f"table {self.anchor!r}", "(no unique table with this header)", None)]
        out = _cite(t, self.sources, self.anchor)
        expected = self.rows()
        seen = set()
        for row in t.rows:
            key = t.key(row, self.key_cols)
            where = f"table {self.anchor!r} row {' | '.join(key)!r}"
            if key not in expected:
                out.append(Mismatch(where, "(row)", "(no such artifact row)"))
                continue
            seen.add(key)
            cells = row[self.key_cols:]
            exp = expected[key]
            if len(exp) != len(cells):
                out.append(Mismatch(where, f"{len(cells)} cells", f"{len(exp)} expected"))
                continue
            for k, ((cell, off), e) in enumerate(zip(cells, exp)):
                _compare(e, cell, off, f"{where} col {self.key_cols + k + 1}", out)
        for key in expected.keys() - seen:
            out.append(Mismatch(f"table {self.anchor!r}", "(row missing)", " | ".join(key)))
        return out


@dataclass
class Verbatim:
    """A README table equal to the study's rendering of an artifact (`render` returns the
    markdown that contains it; the table with the same header line is taken)."""

    anchor: str
    sources: tuple[str, ...]
    render: Callable[[], str]

    def check(self, text: str, tables: list[MdTable]) -> list[Mismatch]:
        t = _find_table(tables, self.anchor)
        if t is None:
            return [Mismatch(f"table {self.anchor!r}", "(no unique table with this header)", None)]
        out = _cite(t, self.sources, self.anchor)
        want = [x for x in md_tables(self.render()) if self.anchor in x.header]
        if len(want) != 1:
            return out + [Mismatch(f"table {self.anchor!r}", "(table)", "(not in the artifact)")]
        w = self.render()[want[0].start:want[0].end]
        have = text[t.start:t.end]
        if [ln.strip() for ln in have.splitlines()] != [ln.strip() for ln in w.splitlines()]:
            out.append(Mismatch(f"table {self.anchor!r} (verbatim)", "(table differs)",
                                "(artifact rendering)", (t.start, t.end),
                                w if w.endswith("\n") else w + "\n"))
        return out


@dataclass
class Sentence:
    """Numbers (or met / missed) of one README sentence: `pattern`'s groups, in order."""

    pattern: str
    sources: tuple[str, ...]
    values: Callable[[], list]
    regex: re.Pattern = field(init=False)

    def __post_init__(self):
        self.regex = re.compile(self.pattern.replace(" ", r"\s+"))

    def check(self, text: str, tables: list[MdTable]) -> list[Mismatch]:
        hits = list(self.regex.finditer(text))
        where = f"sentence {self.pattern[:60]!r}"
        if len(hits) != 1:
            return [Mismatch(where, f"({len(hits)} matches)", "(exactly one expected)")]
        m, out = hits[0], []
        for g, e in enumerate(self.values(), start=1):
            s = m.group(g)
            if isinstance(e, Verdict):
                if s != e.word:
                    out.append(Mismatch(where, s, e.word, m.span(g), e.word))
            elif e is not None:
                _compare([e], s, m.start(g), where, out)
        return out


@dataclass
class Claim:
    """Prose that is true only while `holds()` is (e.g. "that run predates …"): the README
    must contain `pattern` exactly when it holds; a person rewrites the prose otherwise."""

    pattern: str
    sources: tuple[str, ...]
    holds: Callable[[], bool]
    why: str

    def check(self, text: str, tables: list[MdTable]) -> list[Mismatch]:
        present = re.search(self.pattern.replace(" ", r"\s+"), text) is not None
        if present != bool(self.holds()):
            return [Mismatch(f"claim {self.pattern[:60]!r}",
                             "present" if present else "absent", self.why)]
        return []


def _cite(t: MdTable, sources, anchor) -> list[Mismatch]:
    stems = {"figures/" + s.rsplit(".", 1)[0] for s in sources}
    if not any(s in t.caption for s in stems):
        return [Mismatch(f"table {anchor!r}", "(caption)",
                         f"caption names none of {sorted(stems)}")]
    return []


# ------------------------------------------------------------------ the README's quoted numbers


def _bench_row(path):
    return next(r for r in artifact("bench.json")["rows"] if r["path"] == path)


def _us(path):
    return _bench_row(path)["warm_s_per_eval"] * 1e6


def _fig7_rows():
    e = artifact("figure7.json")["errors_vs_reference"]
    out = {}
    for label, row in (("(a)–(d) θₒ × √α", "roughness"), ("(e)–(h) θₒ × d", "thickness")):
        for m in ("ideal", "filtered_gt_moments", "filtered_gt_opd"):
            s = e[f"{row}/{m}"]
            out[(label, f"`{m}`")] = [s["dE2000_mean"], s["dE2000_p95"], s["dE2000_max"],
                                      s["band_abs_max"]]
    return out


def _fig7_costs():
    f = artifact("figure7_timing.json")  # written by `make bench`, not by `make figure7`
    n = f["config"]["resolution"] ** 2
    sec = f["seconds_per_method"]
    return [f["config"]["resolution"], None, 2 * n, f["compute_seconds"],
            f["load_average"][0], n] + [sec[f"thickness/{m}"] / n * 1e6 for m in
                                        ("ideal", "filtered_gt_moments", "filtered_gt_opd")] \
        + [sec["thickness/reference"] / n * 1e3]


def _ibl_render_rows():
    out = {}
    for r in artifact("ibl_render.json")["renders"]:
        e = r["dE2000"]
        out[(f"{r['scene']}: {r['label'].replace(' | ', ', ')}",)] = [
            [e[m]["mean"], e[m]["p95"]] for m in ("ideal", "filtered", "improved")]
    return out


def _ibl_markdown():
    from benchmarks.ibl_bench import markdown

    return markdown(artifact("ibl_bench.json"))


def _frame_size_rows():
    """The last run of the per-size bench: ratios and ns a point per size (default chunk)."""
    run = artifact("kernel_bench_sizes.json")["runs"][-1]
    names = {65536: "65,536", 1048576: "2²⁰", 3686400: "1440p (3,686,400)"}
    out = {}
    for r in run["ratios"]:
        if r["batch_size"] is None and r["points"] in names:
            ns = {x["kernel"]: x["ns_per_point"] for x in run["rows"]
                  if x["points"] == r["points"] and x["batch_size"] is None}
            out[(names[r["points"]],)] = [
                r["filtered / ideal"], r["improved / filtered"],
                r["improved+sun / filtered+sun"],
                [ns["envmap ideal"], ns["envmap filtered"], ns["envmap improved"]]]
    return out


def _kernel_bench_sentence():
    rows = {(r["kernel"], r["version"]): r["ns_per_point"]
            for r in artifact("kernel_bench.json")["rows"]}
    speed = artifact("kernel_bench.json")["speedup_old_over_new"]
    times = [v["time"] for v in speed.values()]
    return [min(times), max(times)] + [rows[(k, "new")] for k in (
        "filtered_kernel", "ideal_kernel", "improved_kernel", "envmap ideal",
        "envmap filtered", "envmap improved")] + [speed["envmap improved"]["time"]]


def _improved_cost_sentence():
    ns = {r["kernel"]: r["ns_per_point"] for r in artifact("kernel_bench.json")["rows"]
          if r["version"] == "new"}
    f, i = ns["envmap filtered"], ns["envmap improved"]
    fs, is_ = ns["envmap filtered + 1 sun"], ns["envmap improved + 1 sun"]
    return [ns["improved_kernel"], ns["filtered_kernel"],
            ns["improved_kernel"] / ns["filtered_kernel"], f, i, i / f, fs, is_, is_ / f,
            is_ / fs]


def _reference_bench_sentence():
    r = artifact("reference_bench.json")
    by = {(x["version"], x["alpha"]): x["points_per_s"] for x in r["rows"]}
    sp = r["speedup"]["old 1"]
    return [sp["0.25"], sp["0.6"], by[("new", 0.25)], by[("new", 0.6)], by[("old 1", 0.25)],
            by[("old 1", 0.6)], sp["0.05"], by[("old 2", 0.25)]]


def _ibl_frame_ratios():
    tp = artifact("ibl_bench.json")["throughput"]
    rows = {r["name"]: r["warm_s"] for r in tp}
    ideal_ns = rows["ideal"] / next(r["points"] for r in tp if r["name"] == "ideal") * 1e9
    run = artifact("kernel_bench_sizes.json")["runs"][-1]
    grid_ns = next(r["ns_per_point"] for r in run["rows"] if r["points"] == 3686400
                   and r["batch_size"] is None and r["kernel"] == "envmap ideal")
    return [rows["filtered (LUT)"] / rows["ideal"],
            rows["improved (LUT)"] / rows["filtered (LUT)"], ideal_ns, grid_ns]


def _bins_markdown():
    from benchmarks.small_sources import bins_markdown

    return bins_markdown(artifact("improved_bins.json"))


def _bins_cost():
    ns = artifact("improved_bins.json")["cost"]["ns_per_point"]
    f = ns["filtered"]
    return [ns["ideal"], f] + [x for k in ("K=2", "K=3", "K=4", "K=3 + spread") for x in (
        ns[f"improved {k}"], ns[f"improved {k}"] / f)] + [
        ns["improved K=3 + spread"] / ns["improved K=3"]]


def _bins_reads_cost():
    ns = artifact("improved_bins.json")["cost"]["ns_per_point"]
    f = ns["filtered"]
    return [x for k in ("K=3, 2 reads", "K=3, 3 reads", "K=3, 3 reads + spread") for x in (
        ns[f"improved {k}"], ns[f"improved {k}"] / f)]


def _bins_target_met(variant):
    """Every render of the bins sweep within improved's targets (≤ 3 ΔE₀₀, ≤ 0.7× filtered)."""
    rows = artifact("improved_bins.json")["rows"]
    return all(r[variant] <= 3.0 and r[variant] <= 0.7 * r["filtered"] for r in rows)


def _bins_frontier():
    """(settings within 1.5× filtered, settings that meet the accuracy target, cheapest first)
    of the bins sweep, and the numbers the performance page quotes for them."""
    ns = artifact("improved_bins.json")["cost"]["ns_per_point"]
    ratio = {k[len("improved "):]: v / ns["filtered"] for k, v in ns.items()
             if k.startswith("improved ")}
    cheap = [k for k in ratio if ratio[k] <= 1.5]
    accurate = sorted((k for k in ratio if _bins_target_met(k)), key=ratio.get)
    return cheap, accurate, ratio


def _bins_frontier_as_stated():
    """No setting both within 1.5× filtered and accurate; K = 2 the only cheap one, K = 3
    with 3 reads a bin the cheapest accurate one."""
    cheap, accurate, _ = _bins_frontier()
    return cheap == ["K=2"] and accurate[:1] == ["K=3, 3 reads"] and not set(cheap) & set(accurate)


def _bins_frontier_numbers():
    _, accurate, ratio = _bins_frontier()
    rows = artifact("improved_bins.json")["rows"]
    return [ratio["K=2"], sum(r["K=2"] > 3.0 for r in rows),
            max(r["K=2"] / r["filtered"] for r in rows), ratio[accurate[0]]]


def _small_sources_markdown():
    from benchmarks.small_sources import markdown

    return markdown(artifact("small_sources.json"))


def _photo_markdown():
    from benchmarks.photo_study import markdown

    return markdown(artifact("photo_study.json"))


def _ibl_vs_ideal(name):
    rows = artifact("ibl_bench.json")["throughput"]
    return next(r for r in rows if r["name"] == name)["vs_ideal"]


def _models_rows():
    d = artifact("models.json")
    st = {(r["family"], r["film"]): r for r in d["schlick_tint"]}
    fm = {(r["grid"], r["method"]): r for r in d["film_methods"]}
    pair = lambda r: [r["dE2000_mean"], r["dE2000_p95"]]  # noqa: E731
    return {(film,): [pair(st[("ggx", film)]), pair(st[("cook_torrance", film)])]
            + [pair(fm[(film, m)]) for m in ("khr", "ideal", "filtered", "improved")]
            for (fam, film) in st if fam == "ggx"}


def _improved_rows():
    d = artifact("improved.json")
    u = d["uniform"]

    def pair(s):
        return [[s["filtered"]["mean"], s["filtered"]["p95"]],
                [s["improved"]["mean"], s["improved"]["p95"]], [s["ratio_mean"], s["ratio_p95"]]]

    k = {r["path"]: r for r in d["kernels"]}
    f, i = k["filtered K29 (shipped: bicubic LUT)"], k["improved K=3 (default: bilinear LUT)"]
    return {
        ("uniform light, wide grid (4 films, κ₃ 0–3.99, d ≤ 1000 nm, θₒ ≤ 88°, α 0.01–0.9)",):
            pair(u["wide"]["all"]),
        ("uniform light, Figure 7 (a)–(d) grid, 32²",): pair(u["figure7 roughness"]["all"]),
        ("uniform light, Figure 7 (e)–(h) grid, 32²",): pair(u["figure7 thickness"]["all"]),
        ("IBL, the twelve sphere renders (four shipped maps)",): pair(d["ibl"]["all"]),
        ("cost per shading point, float32, uniform-light kernel (2-core CPU)",):
            [f["us_per_point"], i["us_per_point"], i["cost_vs_filtered"]],
    }


def _improved_map_rows():
    """The per-map table: every pixel of a map's renders pooled (mean / p95 / the worst
    render's mean) for filtered, improved and filtered + sources, and improved ÷ filtered."""
    ibl = artifact("improved.json")["ibl"]

    def row(g):
        return [g["renders"]] + [[g[m]["mean"], g[m]["p95"], g[m]["worst_render_mean"]]
                                 for m in ("filtered", "improved", "filtered+sources")] + [
            [g["ratio_mean"], g["ratio_p95"]]]

    out = {(m,): row(g) for m, g in ibl["per_map"].items()}
    out.update({(f"held out: {m}",): row(g) for m, g in ibl["held_out"]["per_map"].items()})
    out[("all pixels, the four shipped maps",)] = row(ibl["all"])
    return out


def _improved_forest():
    g = artifact("improved.json")["ibl"]["per_map"]["forest_slope"]
    return [g["ratio_mean"], g["ratio_p95"]]


def _improved_every_map_meets() -> bool:
    """The target (improved ÷ filtered ≤ 0.5 in mean and p95) is met on every shipped and
    held-out map and over all pixels."""
    ibl = artifact("improved.json")["ibl"]
    maps = {**ibl["per_map"], **ibl["held_out"]["per_map"]}
    return all(max(g["ratio_mean"], g["ratio_p95"]) <= 0.5 for g in maps.values()) and max(
        ibl["all"]["ratio_mean"], ibl["all"]["ratio_p95"]) <= 0.5


def _improved_worse():
    u = artifact("improved.json")["uniform"]
    ex = {e["case"]: e for g in u.values() for e in g["largest_excess"]}
    a, b = ex["soap d=300 θo=88° α=0.06"], ex["soap d=1000 θo=82° α=0.06"]
    th = u["figure7 thickness"]["largest_excess"]
    return [sum(g["all"]["n_worse_by_1"] for g in u.values()),
            sum(g["all"]["improved"]["n"] for g in u.values()),
            a["filtered"], a["improved"], b["filtered"], b["improved"],
            u["figure7 thickness"]["all"]["n_worse_by_1"],
            max(e["improved"] - e["filtered"] for e in th), max(e["improved"] for e in th)]


def _fit_study_rows():
    s = artifact("fit_study.json")["summary"]

    def row(m):
        x = s[m]
        return [x["recovered_fraction"], x["global_minimum_fraction"],
                [x["coverage_1.96se"]["thickness"], x["coverage_1.96se"]["eta_film"]],
                x["median_abs_err"]["thickness"], x["time_per_fit_s"]["mean"]]

    return {("`filtered`",): row("filtered"), ("`filtered` then `reference`",):
            row("filtered+reference"), ("`reference`",): row("reference"),
            ("spectra (`airy_reflectance`)",): row("spectrum(airy)")}


def _coverage_rows():
    g = artifact("coverage_global.json")["global"]["reference"]
    c = artifact("coverage.json")["coverage"]["reference"]
    return {("noise-free (`--n-global 100`)",): [
                None, None, [g["global_minimum_fraction"] * g["n"], g["n"]],
                g["ambiguous_fraction"] * g["n"], [g["time_per_fit_s"], None]],
            ("1 % Gaussian noise (`--n-coverage 200`)",): [
                None, None, [c["right_basin_fraction"] * c["n"], c["n"]],
                c["ambiguous_fraction"] * c["n"], c["time_per_fit_s"]]}


def _coverage_z_rows():
    c = artifact("coverage.json")["coverage"]["reference"]
    out = {}
    for label, p in (("d", "thickness"), ("η₂", "eta_film"), ("α", "alpha")):
        out[(label,)] = [c["coverage"][p]["1se"], c["coverage"][p]["2se"],
                         c["t_interval_coverage"][p]["0.683"], c["t_interval_coverage"][p]["0.954"],
                         c["median_abs_z"][p]]
    out[("expected",)] = [c["nominal_student_t"]["1se"], c["nominal_student_t"]["2se"],
                          c["nominal"]["1se"], c["nominal"]["2se"], None]
    return out


def _coverage_miss():
    fits = artifact("coverage.json")["per_fit"]["reference"]["coverage"]
    (m,) = [r for r in fits if not r["right_basin"]]
    t, f = m["truth"], m["fit"]
    return [t["thickness"], t["eta_film"], t["alpha"], f["thickness"], f["eta_film"], f["alpha"]]


def _fit_map_rows():
    out = {}
    for img, name in (("wedge, uniform light", "fit_map_demo.json"),
                      ("bubble, environment map", "fit_map_demo_envmap.json")):
        for prior, key in (("none", "independent"), ("τ = 50 nm", "prior_tau50nm")):
            x = artifact(name)["fits"][key]
            out[(img, prior)] = [x["median_abs_nm"], x["p95_abs_nm"], x["max_abs_nm"],
                                 x["fraction_over_20nm"] * 100, x["pixels_per_second_warm"],
                                 x["compile_seconds"] if key == "independent" else None]
    return out


def _fit_map_machine():
    w, e = artifact("fit_map_demo.json"), artifact("fit_map_demo_envmap.json")
    loads = [w["machine"]["load_average_1_5_15"][0], e["machine"]["load_average_1_5_15"][0]]
    return [min(loads), max(loads), e["prefilter_seconds"]]


_EVR = {  # README row of the error-vs-run-time table -> bench.json row paths
    "shading point: spectral reference (89 λ, f64)": ["spectral (reference)"],
    "shading point: Fourier M = 1 / 2 / 4 / 8": [f"Fourier M={m}" for m in (1, 2, 4, 8)],
    "shading point: Fourier M = 2 with Gaussian Ŝ, f32": ["Fourier M=2, Gaussian Ŝ f32"],
    "shading point: spectral f32": ["spectral f32"],
    "patch: reference quadrature 16² / 32² / 48²":
        [f"reference quadrature {n}²" for n in (16, 32, 48)],
    "patch: Monte Carlo 10³ / 10⁴ / 10⁵ samples": [f"Monte Carlo 1e+0{k}" for k in (3, 4, 5)],
    "patch: `ideal` / `filtered` / `filtered_gt_moments` / `filtered_gt_opd`":
        ["ideal", "filtered", "filtered_gt_moments", "filtered_gt_opd"],
    "patch: `improved` fast / default / accurate, `khr`":
        ["improved fast (K=2)", "improved default (K=3)",
         "improved accurate (K=3, 3 reads a bin: under uniform light = K=3)", "khr"],
    "real-time kernel (f32): ideal M = 2 / K 29 with LUT / K 29 with Gaussian Ŝ":
        ["kernel ideal M=2 f32", "kernel K29 LUT f32", "kernel K29 Gaussian Ŝ f32"],
}


def _evr_rows():
    out = {}
    for label, paths in _EVR.items():
        rs = [_bench_row(p) for p in paths]
        dmax = [r["dE_max"] for r in rs]
        if label.startswith("shading point: Fourier M = 1"):
            dmax = dmax + [None]  # "(grazing, d → 0)"
        out[(label,)] = [[r["dE_p95"] for r in rs], dmax,
                         [r["warm_s_per_eval"] * 1e6 for r in rs]]
    return out


def _peers_markdown():
    from benchmarks.peers import peers_table

    return peers_table(artifact("peers.json"))


def _peer(grid, key):
    return artifact("peers.json")["grids"][grid]["speedup_airy_vs"][key]


def _spec_rows():
    s = {(r["baseline"], r["specialised"], r["films"]): r
         for r in artifact("specialisation.json")["rows"]}

    def r(b, sp, f):
        return s[(b, sp, f)]

    def saved(*rows):
        return [x["time_saved"] * 100 for x in rows]

    diel = [r("ideal M=2, general", "ideal M=2, dielectric", "dielectric"),
            r("K29 LUT, general", "K29 LUT, dielectric", "dielectric")]
    mirror = r("K29 Gaussian Ŝ", "ideal M=2, Gaussian Ŝ", "absorbing")
    mirror_lut = r("K29 LUT", "ideal M=2", "absorbing")
    band = [r("ideal M=2", "ideal M=2, band G only", "absorbing"),
            r("K29 exact Ŝ", "K29 exact Ŝ, band G only", "absorbing")]
    m2 = r("ideal M=4", "ideal M=2", "absorbing")
    m1 = [r("ideal M=2", "ideal M=1", "absorbing"), r("K29 LUT", "K29 LUT M=1", "absorbing")]
    lut = r("K29 exact Ŝ", "K29 LUT", "absorbing")
    gauss = [r("K29 exact Ŝ", "K29 Gaussian Ŝ", "absorbing"),
             r("ideal M=2", "ideal M=2, Gaussian Ŝ", "absorbing")]
    bare = r("ideal M=2", "Fresnel only", "bare")
    return {
        ("dielectric base (κ₃ = 0, no TIR)",): [None, None, saved(*diel), [
            max(x["dE_added_p95"] for x in diel), max(x["dE_added_max"] for x in diel),
            max(x["band_abs_added_max"] for x in diel)]],
        ("near-mirror surface",): [None, None, saved(mirror), [
            mirror["dE_added_p95"], mirror["dE_added_max"], None,
            mirror["dE_added_p95_all_alpha"]]],
        ("near-mirror surface, tabulated Ŝ",): [None, None, saved(mirror_lut), None],
        ("one band needed",): [None, None, saved(*band), [max(x["dE_added_max"] for x in band)]],
        ("M = 2 is enough",): [None, None, saved(m2), [
            m2["dE_added_p95"], m2["dE_added_max"], m2["baseline_dE_vs_reference_max"],
            m2["specialised_dE_vs_reference_max"]]],
        ("M = 1 is enough",): [None, None, saved(*m1), [
            m1[0]["dE_added_p95"], m1[0]["dE_added_max"], m1[1]["dE_added_p95"],
            m1[1]["dE_added_max"]]],
        ("Ŝ from a table",): [None, None, saved(lut), [lut["dE_added_p95"], lut["dE_added_max"]]],
        ("Ŝ from a closed form",): [None, None, saved(*gauss), [
            max(x["dE_added_p95"] for x in gauss), max(x["dE_added_max"] for x in gauss)]],
        ("no film (d = 0)",): [None, None, saved(bare) + [bare["speedup"]], [
            None, bare["specialised_dE_vs_reference_max"], None,
            bare["baseline_dE_vs_reference_max"]]],
    }


def _ibl_reference_rate(kind: str, alpha: str) -> float:
    """Points/s of the `kind` reference row of ibl_bench.json at α = `alpha`."""
    return next(r["points_per_s"] for r in artifact("ibl_bench.json")["throughput"]
                if r["name"].startswith(f"reference, {kind} ") and f"α = {alpha}," in r["name"])

def _ibl_sphere_row() -> dict:
    """The whole-sphere reference row of ibl_bench.json."""
    return next(r for r in artifact("ibl_bench.json")["throughput"]
                if r["name"].startswith("reference, 256 px sphere"))


def _bench_load():
    """CPUs and load of the run behind the peers, specialisation and stability sections (the
    error-vs-run-time rows may have been rerun alone since: "environment" is theirs)."""
    b = artifact("bench.json")
    env = b.get("environment_other_sections", b["environment"])
    return [env["cpu_count"], env["load_average"][0]]


def _presets_rows():
    films = artifact("presets_bench.json")["films"]
    names = {"`ideal`": "ideal", "`filtered`": "filtered",
             '`improved`, `ModelOptions.preset("fast")` (K = 2)': "improved (fast)",
             '`improved`, `preset("default")` (K = 3)': "improved (default)",
             '`improved`, `preset("accurate")` (K = 3, three reads a bin)': "improved (accurate)"}
    d, a = films["dielectric"]["rows"], films["absorbing base"]["rows"]
    return {(label,): [d[k]["ns_per_point"], d[k]["x_filtered"], a[k]["ns_per_point"],
                       a[k]["x_filtered"], d[k]["first_call_s"]]
            for label, k in names.items()}


def _method_cost(*names):
    """× `filtered` of rows `names` of method_cost.json (a method, or "improved <preset>")."""
    rows = {r["name"]: r for r in artifact("method_cost.json")["rows"]}
    return [rows[n]["x_filtered"] for n in names]


SPECS = [
    Sentence(r"`improved` costs \*\*(\S+)×\*\* `filtered` a shading point with "
             r"`ModelOptions.preset\(\"fast\"\)` \(K = 2\), \*\*(\S+)×\*\* with the default "
             r"\(K = 3\) and \*\*(\S+)×\*\* with `preset\(\"accurate\"\)` \(three reads a bin\); "
             r"`ideal` (\S+)×, `khr` (\S+)×; `colour_table` (\S+)× `filtered` on the same points "
             r"of one film at one α \(its table's build apart\); the float64 references are "
             r"10⁴–10⁶ times slower \(`reference` (\S+)×, `mc` (\S+)×\)", ("method_cost.json",),
             lambda: _method_cost("improved fast", "improved default", "improved accurate",
                                  "ideal", "khr", "colour_table", "reference", "mc")),
    Sentence(r"`colour_table` \(one film\) \| (\S+) / (\S+) / (\S+); (\S+); (\S+); (\S+) \|",
             ("method_cost.json",),
             lambda: _method_cost("improved fast", "improved default", "improved accurate",
                                  "ideal", "khr", "colour_table")),
    Table("| method | dielectric: ns a point | × `filtered` | absorbing base: ns a point |",
          ("presets_bench.json",), 1, _presets_rows),
    Table("| row | method | ΔE₀₀ mean |", ("figure7.json",), 2, _fig7_rows),
    Table("| render (64 px sphere) |", ("ibl_render.json",), 1, _ibl_render_rows),
    Verbatim("| method | s / frame |", ("ibl_bench.json",), _ibl_markdown),
    Verbatim("| real-time option (", ("ibl_bench.json",), _ibl_markdown),
    Sentence(r"`filtered` costs \*\*(\S+)×\*\* `ideal` per shading point", ("ibl_bench.json",),
             lambda: [_ibl_vs_ideal("filtered (LUT)")]),
    Sentence(r"adaptive (\S+) / (\S+) / (\S+) points/s at α = 0.05 /\s+0.25 / 0.6 against "
             r"(\S+) / (\S+) / (\S+) for the exhaustive rule", ("ibl_bench.json",),
             lambda: [_ibl_reference_rate(kind, a) for kind in ("adaptive", "exhaustive")
                      for a in ("0.05", "0.25", "0.6")]),
    Sentence(r"a whole 256 px sphere\s+\((\S+) points, α = 0.25\) takes (\S+) s warm",
             ("ibl_bench.json",), lambda: [_ibl_sphere_row()["points"], _ibl_sphere_row()["warm_s"]]),
    Table("| ΔE₀₀ vs reference (mean / p95) |", ("improved.json",), 1, _improved_rows),
    Table("| film (uniform light, θₒ 0–85°", ("models.json",), 1, _models_rows),
    Table("| map (pooled pixels) |", ("improved.json",), 1, _improved_map_rows),
    Sentence(r"only the bins act \(improved ÷ filtered (\S+) / (\S+);",
             ("improved.json",), _improved_forest),
    Claim(r"under every held-out map and on every map, including the overcast", ("improved.json",),
          _improved_every_map_meets,
          "a map misses improved ÷ filtered ≤ 0.5: rewrite the sentence after the per-map "
          "table"),
    Sentence(r"\((\S+) of (\S+) patches, all at θₒ ≥ 80°\).*? \((\S+) → (\S+); M = 2 truncation"
             r"(?s:.*?)α = 0.06 \((\S+) → (\S+)\) and the Figure 7 film at d ≈ 870–935 nm, "
             r"θₒ ≥ 80°, "
             r"α = 0.25 \((\S+) patches, at most \+(\S+), improved ≤ (\S+)\)", ("improved.json",),
             _improved_worse),
    Sentence(r'\(`figures/improved.json` "kernels"; load average (\S+) at its start\)',
             ("improved.json",),
             lambda: [artifact("improved.json")["environment"]["load_average"][0]]),
    Claim(r"\(`figures/ibl_bench.md`\), not in the committed run yet", ("ibl_bench.json",),
          lambda: not any(r["name"].startswith("improved")
                          for r in artifact("ibl_bench.json")["throughput"]),
          "ibl_bench.json now times method='improved': quote its cost and ratio in the improved "
          "section instead of 'not in the committed run yet'"),
    Table("| forward model | recovered within tolerance |", ("fit_study.json",), 1,
          _fit_study_rows),
    Table("| study | films | free | in the right minimum |",
          ("coverage_global.json", "coverage.json"), 1, _coverage_rows),
    Table("| parameter | ±1 SE | ±2 SE |", ("coverage.json",), 1, _coverage_z_rows),
    Sentence(r"The one miss \(d = (\S+) nm, η₂ = (\S+), α = (\S+) from four views 10–60°, "
             r"fitted (\S+) nm, (\S+), ([\d.]+)\)", ("coverage.json",), _coverage_miss),
    Table("| image | prior | median \\|Δd\\| nm |",
          ("fit_map_demo.json", "fit_map_demo_envmap.json"), 2, _fit_map_rows),
    Sentence(r"under a load average of (\S+)–(\S+) from other jobs: timings are pessimistic; "
             r"compile = cold − warm run; prefiltering the map took (\S+) s",
             ("fit_map_demo.json", "fit_map_demo_envmap.json"), _fit_map_machine),
    Sentence(r"all eight (\d+) × \d+ panels \((\d) × (\S+) patches\) in \*\*(\S+) s\*\* including "
             r"compilation, at a load average of (\S+) \(`figures/figure7_timing.json`\)\. Cost per "
             r"patch of row \(e\)–\(h\) \(the method's time over its (\S+) patches, its "
             r"compilation "
             r"included\): `ideal` (\S+) µs, `filtered_gt_moments` (\S+) µs, `filtered_gt_opd` "
             r"(\S+) µs, `reference` (\S+) ms", ("figure7_timing.json",), _fig7_costs),
    Sentence(r"Measured on the (\d+)-core CPU of this project's machines \(no GPU was available\), "
             r"at a load average of (\S+) from other jobs at the start of the run",
             ("bench.json",), _bench_load),
    Table("| path | ΔE₀₀ p95 | ΔE₀₀ max | µs / evaluation |", ("bench.json",), 1, _evr_rows),
    Sentence(r"These rows ran on the (\d+)-core CPU at a load average of (\S+) at their start",
             ("bench.json",), lambda: [artifact("bench.json")["environment"]["cpu_count"],
                                       artifact("bench.json")["environment"]["load_average"][0]]),
    Sentence(r"no small M converges; below 80° ΔE max < 1 needs M = (\d+) \(tabulated Ŝ\)",
             ("bench.json",), lambda: [artifact("bench.json")["m_selection"]["exact"][
                 "smallest_M_dE_max_below_1_theta_le_80deg"]]),
    Verbatim("| grid | airy value µs |", ("peers.json",), _peers_markdown),
    Sentence(r"the minimum of 9\): `improved_kernel` (\S+) ns against (\S+) ns for "
             r"`filtered_kernel`\s+\((\S+)×(?s:.*?)`envmap_radiance` takes (\S+) ns with "
             r"`filtered`,\s+(\S+) ns with `improved` \((\S+)×(?s:.*?)sun split from the map "
             r"(\S+) ns \(`filtered`\) and (\S+) ns \(`improved`\): `improved` with its sun"
             r"\s+costs (\S+)× `filtered` as published \((\S+)× `filtered` with the same "
             r"split\)", ("kernel_bench.json",),
             _improved_cost_sentence),
    Sentence(r"\*\*met\*\*,\s+(\S+)× and (\S+)× at α = 0.25 and 0.6 \((\S+) and (\S+) points/s "
             r"against (\S+) and (\S+)\), (\S+)× at\s+α = 0.05(?s:.*?)baadfe4(?s:.*?) at (\S+) "
             r"points/s: the difference",
             ("reference_bench.json",), _reference_bench_sentence),
    Sentence(r"included, warm minima of 3 interleaved rounds: there `filtered` costs (\S+)× "
             r"`ideal` and\s+`improved` (\S+)× "
             r"`filtered`,(?s:.*?)`ideal` takes (\S+) ns a point there,\s+(\S+) ns jitted",
             ("ibl_bench.json", "kernel_bench_sizes.json"), _ibl_frame_ratios),
    Table("| points | filtered / ideal | improved / filtered |", ("kernel_bench_sizes.json",), 1,
          _frame_size_rows),
    Sentence(r"\*\*met\*\* by all six: (\S+)–(\S+)×\s+\(`filtered_kernel` (\S+) ns a point,\s+"
             r"`ideal_kernel` (\S+), `improved_kernel` (\S+);\s+`envmap_radiance` ideal (\S+), "
             r"filtered (\S+), improved (\S+); `envmap improved` is (\S+)×\)",
             ("kernel_bench.json",), _kernel_bench_sentence),
    Claim(r"Real-time kernels ≥ 5× faster than at 6b7cf29 \(float32, 65,536 points, old and "
          r"new interleaved in one run, `figures/kernel_bench.md`\): \*\*met\*\* by all six",
          ("kernel_bench.json",),
          lambda: min(v["time"] for v in
                      artifact("kernel_bench.json")["speedup_old_over_new"].values()) >= 5.0,
          "the docs say every kernel is ≥ 5× 6b7cf29 exactly when kernel_bench.json's "
          "speed-ups are; after a new run, rewrite the sentence"),
    Verbatim("| set | map | render | filtered | K=2 |", ("improved_bins.json",), _bins_markdown),
    Sentence(r"minimum of 5 interleaved rounds\): ideal (\S+) ns, filtered (\S+) ns, "
             r"improved K = 2 (\S+) ns\s+\((\S+)× filtered\), K = 3 (\S+) ns \((\S+)×\), "
             r"K = 4 (\S+) ns \((\S+)×\),\s+K = 3 with `light_spread` (\S+) ns \((\S+)×; (\S+)× "
             r"K = 3\)", ("improved_bins.json",), _bins_cost),
    Sentence(r"K = 3 with 2 reads a bin (\S+) ns\s+\((\S+)×\), with 3 reads (\S+) ns \((\S+)×\), "
             r"with 3 reads and `light_spread` (\S+) ns \((\S+)×\)", ("improved_bins.json",),
             _bins_reads_cost),
    Claim(r"\*\*met with three\s+reads a bin\*\*", ("improved_bins.json",),
          lambda: _bins_target_met("K=3, 3 reads") and _bins_target_met("K=3, 3 reads + spread"),
          "the study page says three reads a bin meet improved's accuracy target exactly when "
          "every render of improved_bins.json does, with and without light_spread"),
    Claim(r"\*\*K = 3 with 3 reads a bin meets the accuracy target on all 18 renders\*\*",
          ("improved_bins.json",), lambda: _bins_target_met("K=3, 3 reads"),
          "the study page says three reads a bin meet the accuracy target exactly when "
          "improved_bins.json's renders do"),
    Claim(r"\*\*No setting of the bins sweep meets both targets\*\*", ("improved_bins.json",),
          _bins_frontier_as_stated,
          "the performance page says no setting is both within 1.5× filtered and within the "
          "accuracy target, that K = 2 is the only one within 1.5× and K = 3 with 3 reads the "
          "cheapest accurate one, exactly when improved_bins.json says so"),
    Sentence(r"the only one within 1.5× `filtered` is K = 2 \((\S+)×\), which leaves (\S+) "
             r"renders above 3 mean ΔE₀₀ \(worst ratio (\S+)\); the cheapest that meets the "
             r"accuracy target of the small-sources study \(≤ 3 mean ΔE₀₀ and ≤ 0.7× "
             r"`filtered` on every render\) is K = 3 with 3 reads a bin, at (\S+)×",
             ("improved_bins.json",), _bins_frontier_numbers),
    Verbatim("| set | map | render | filtered | improved (before) |", ("small_sources.json",),
             _small_sources_markdown),
    Verbatim("| case | median \\|err\\| nm | p95 nm |", ("photo_study.json",), _photo_markdown),
    Verbatim("| case | against | median", ("photo_study.json",), _photo_markdown),
    Verbatim("| d nm | fringes | spectrum |", ("photo_study.json",), _photo_markdown),
    Sentence(r"`thin_film_tmm` disagrees with `tmm` by up to (\S+) for absorbing", ("peers.json",),
             lambda: [max(g["max_abs_diff"]["colour_vs_tmm"]
                          for g in artifact("peers.json")["grids"].values())]),
    Sentence(r"The committed file is the peers part of the `make bench` run in "
             r"`figures/bench.json`, "
             r"load average (\S+) at its start", ("peers.json",),
             lambda: [artifact("peers.json")["environment"]["load_average"][0]]),
    Claim(r"That run predates the present `airy_reflectance`", ("peers.json",),
          lambda: "predates" in (artifact("peers.json").get("note") or ""),
          "the README says the peers run predates airy_reflectance's rewrite exactly when "
          "peers.json's note says so; after a new run, rewrite the NumPy-target paragraph"),
    Sentence(r"(?s:`airy_reflectance` ≥ 100× `tmm`'s loop per evaluation: \*\*(met|missed)\*\* "
             r"\((\S+)–(\S+)×\))", ("peers.json",),
             lambda: [Verdict(artifact("peers.json")["targets"]["airy_vs_tmm"]["met"]),
                      artifact("peers.json")["targets"]["airy_vs_tmm"]["min"],
                      artifact("peers.json")["targets"]["airy_vs_tmm"]["max"]]),
    Sentence(r"10⁶ pairs: \*\*(met|missed)\*\* in `figures/peers.json`: absorbing base "
             r"\(fig7\) (\S+)× on the grid, (\S+)× flat; dielectric base \(tio2_glass\) (\S+)× / "
             r"(\S+)×", ("peers.json",),
             lambda: [Verdict(artifact("peers.json")["targets"]["airy_vs_numpy_1e6"]["met"]),
                      _peer("fig7/1000x1000", "numpy_closed_form"),
                      _peer("fig7/1000x1000", "numpy_closed_form_flat"),
                      _peer("tio2_glass/1000x1000", "numpy_closed_form"),
                      _peer("tio2_glass/1000x1000", "numpy_closed_form_flat")]),
    Sentence(r"shading points/s: \*\*(met|missed)\*\* — (\S+)/s \(`figures/bench.json`\)\. "
             r"(?s:.*?)the Gaussian-Ŝ closed form reaches (\S+)/s", ("bench.json",),
             lambda: [Verdict(1e6 / _us("kernel K29 LUT f32") >= 1e7),
                      1e6 / _us("kernel K29 LUT f32"), 1e6 / _us("kernel K29 Gaussian Ŝ f32")]),
    Sentence(r"K 29 cost ≤ 1.5× `ideal`: \*\*(met|missed)\*\* \((\S+)× with LUT vs tabulated-Ŝ "
             r"ideal; (\S+)× with both on the Gaussian Ŝ\)", ("bench.json",),
             lambda: [Verdict(_us("kernel K29 LUT f32") / _us("kernel ideal M=2 f32") <= 1.5),
                      _us("kernel K29 LUT f32") / _us("kernel ideal M=2 f32"),
                      _us("kernel K29 Gaussian Ŝ f32") / _us("kernel ideal M=2 Gaussian Ŝ f32")]),
    Sentence(r"Measured on one batch of (\S+) float32 shading points", ("specialisation.json",),
             lambda: [artifact("specialisation.json")["points"]]),
    Sentence(r"output on the same points\. Load average (\S+) at the start",
             ("specialisation.json",),
             lambda: [artifact("specialisation.json")["environment"]["load_average"][0]]),
    Table("| scene feature | what is left out | baseline → specialised | time saved |",
          ("specialisation.json",), 1, _spec_rows),
]

# Tables whose caption names a figures/ file but that this module does not check, and why.
NOT_CHECKED = {
    "| workload | items | 1 device s |": "the sharding section (figures/scaling.json) is "
                                          "maintained with the scaling study",
}


def check(text: str | None = None) -> list[Mismatch]:
    """Every mismatch between the document (`text`, default the pages) and the artifacts."""
    text = read_document() if text is None else text
    tables = md_tables(text)
    out: list[Mismatch] = []
    for spec in SPECS:
        try:
            out += spec.check(text, tables)
        except (KeyError, StopIteration, ValueError, FileNotFoundError) as e:
            name = getattr(spec, "anchor", None) or spec.pattern[:50]
            out.append(Mismatch(f"{type(spec).__name__} {name!r}",
                                "(artifact lookup failed)", f"{type(e).__name__}: {e}"))
    return out


def unchecked_tables(text: str | None = None) -> list[str]:
    """Header lines of tables that cite a figures/ file in their caption but have no spec."""
    text = read_document() if text is None else text
    anchors = [s.anchor for s in SPECS if hasattr(s, "anchor")] + list(NOT_CHECKED)
    return [t.header for t in md_tables(text)
            if re.search(r"figures/\w+\.(json|md)", t.caption)
            and not any(a in t.header for a in anchors)]


def fix(text: str) -> tuple[str, list[Mismatch]]:
    """`text` with every fixable mismatch rewritten; the mismatches left for a person."""
    mm = check(text)
    todo = sorted((m for m in mm if m.span and m.replacement is not None),
                  key=lambda m: m.span[0], reverse=True)
    last = len(text) + 1
    for m in todo:
        if m.span[1] <= last:
            text = text[:m.span[0]] + m.replacement + text[m.span[1]:]
            last = m.span[0]
    return text, [m for m in mm if not (m.span and m.replacement is not None)]


def main(argv=None) -> int:
    import argparse

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--fix", action="store_true",
                   help="rewrite the docs pages' numbers from the artifacts")
    a = p.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    if a.fix:
        new, left = fix(read_document())
        write_document(new)
        _cache.clear()
        left = check()
        print(f"docs pages rewritten; {len(left)} mismatch(es) left for a person:")
        for m in left:
            print(" ", m)
        return 1 if left else 0
    mm = check()
    for m in mm:
        print(m)
    for h in unchecked_tables():
        print(f"unchecked table citing figures/: {h}")
    print(f"{len(mm)} mismatch(es)")
    return 1 if mm else 0


# ------------------------------------------------------------------------------ tests


def test_readme_numbers_match_artifacts():
    mm = check()
    assert not mm, "docs numbers disagree with their artifacts " \
                   "(`python tests/test_readme_numbers.py --fix`):\n" + "\n".join(map(str, mm))


def test_every_artifact_table_is_checked():
    assert unchecked_tables() == []


def test_number_tokens():
    """Precision and style of printed numbers (the rules in the module docstring)."""
    cases = [("9.18", 9.18, 0.01), ("16,600", 16600, 100), ("5.7e3", 5700, 100),
             ("1.04e+04", 10400, 100), ("2.1·10⁶", 2.1e6, 1e5), ("0", 0, 0), ("914", 914, 1),
             ("−52", -52, 1), ("0.0019", 0.0019, 1e-4), ("3e-5", 3e-5, 1e-5)]
    for s, v, u in cases:
        t = Token.parse(s)
        assert math.isclose(t.value, v) and math.isclose(t.unit, u, abs_tol=0), (s, t)
        assert t.agrees(v) and t.like(v) == s, (s, t.like(v))
    assert Token.parse("9.6").like(3.083) == "3.1" and not Token.parse("9.6").agrees(3.083)
    assert Token.parse("16,600").like(12812.0) == "12,800"
    assert Token.parse("1.6·10⁶").like(2.05e6) in ("2.0·10⁶", "2.1·10⁶")
    assert Token.parse("1.04e+04").like(1.22e5) == "1.22e+05"
    assert Token.parse("5.7e3").like(5.58e3) == "5.6e3"
    assert Token.parse("0.0019").like(0.000123) == "0.00012"
    assert not Token.parse("0").agrees(1e-9) and Token.parse("16,600").agrees(16640)
    found = [m.group(0) for m in NUM_RE.finditer("K 29, 48² x1000 M=2 | 3.1 / 1.2e-3, −4 %; e3")]
    assert found == ["29", "2", "3.1", "1.2e-3", "−4"], found


def test_checker_finds_and_fixes_a_wrong_number():
    """A README with one number changed (the first row of the Figure 7 table) fails the check,
    and `fix` restores the original text."""
    text = read_document()
    t = _find_table(md_tables(text), "| row | method | ΔE₀₀ mean |")
    cell, off = t.rows[0][2]
    tok = NUM_RE.search(cell)
    a, b = off + tok.start(), off + tok.end()
    broken = text[:a] + "77.77" + text[b:]  # same style as 9.18
    mm = check(broken)
    assert len(mm) == 1 and mm[0].readme == "77.77" and mm[0].replacement == text[a:b]
    assert fix(broken)[0] == text


if __name__ == "__main__":
    sys.exit(main())
