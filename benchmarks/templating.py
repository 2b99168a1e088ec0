"""Reports whose prose lives in templates (benchmarks/templates/), not in f-strings: the
studies.stability and studies.stability_light reports, and the tools that fill a template
(first_images).

A study measures into plain data (dicts with string keys, lists, numbers, strings, None:
`plain` makes numpy values so and refuses anything JSON would not give back unchanged), saves
it as JSON beside its report (`save_json`) and writes the report by filling the named blocks
of a template file in benchmarks/templates/ (`blocks`, `fill`: `str.format` fields, the format
specs in the template, every number computed by the study's code, none in the text).

The tests a report quotes are named by (test file, test function) pairs; `pinned_ids` turns them
into the ids the report prints after checking that each function is defined in its file, so a
renamed test stops the report from being written and fails the tests that write it.
`quoted_tests` finds every test id a written report names, for the tests to check.

A study's PINS may be written file by file (`pins_by_file`). Its main(argv) reads its command
line with `study_arguments` (--quick, --threads, --output); `study_text` puts its report
together (header, intro, sections, total) and `write_study` writes the report, its charts and
its JSON side by side.

Not a benchmark: it has no main(argv).
"""
import argparse
import ast
import json
import math
import re
import tempfile
from pathlib import Path

import numba
import numpy as np

from . import report

ROOT = Path(__file__).resolve().parent.parent          # the repository: test files are under it
TEMPLATES = Path(__file__).resolve().parent / "templates"
BLOCK = re.compile(r"^<!-- block: (\w+) -->\n", re.M)
TEST_ID = re.compile(r"(tests/[\w/]+\.py)?::(test_\w+)")


def blocks(name):
    """{block name: text} of benchmarks/templates/<name>. A block runs from its marker line
    `<!-- block: NAME -->` to the next marker or the end of the file, trailing newlines dropped;
    text before the first marker is a note for the reader, not a block."""
    parts = BLOCK.split((TEMPLATES / name).read_text())
    found = {}
    for key, body in zip(parts[1::2], parts[2::2]):
        if key in found:
            raise ValueError(f"{name}: block {key!r} twice")
        found[key] = body.rstrip("\n")
    return found


def fill(template, *sources, **fields):
    """template.format_map of the dicts `sources` merged, then `fields` (later ones win),
    saying which field is missing if one is."""
    values = {}
    for source in sources:
        values.update(source)
    values.update(fields)
    try:
        return template.format_map(values)
    except KeyError as error:
        raise KeyError(f"template field {error} has no value (given: "
                       f"{', '.join(sorted(values))})") from None


def join(template, rows, sep="\n"):
    """fill(template, row) for every row (a dict), joined by sep."""
    return sep.join(fill(template, row) for row in rows)


def plain(value):
    """value as JSON-ready data that json.loads(json.dumps(...)) gives back equal: numpy
    scalars and arrays to Python numbers and lists, tuples to lists. Dict keys must be
    strings and floats finite (TypeError, ValueError otherwise)."""
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f"data keys must be strings, got {key!r}")
            out[key] = plain(item)
        return out
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, (list, tuple)):
        return [plain(item) for item in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value):
            raise ValueError(f"data must be finite, got {value!r}")
        return float(value)
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"not plain data: {value!r} ({type(value).__name__})")


def save_json(report_path, data):
    """Write data (plain) as JSON beside report_path (same name, .json), atomically through
    report.write; return its path."""
    path = Path(report_path).with_suffix(".json")
    return report.write(path, json.dumps(plain(data), indent=1, allow_nan=False) + "\n")


def defined_tests(path):
    """Names of the test functions defined at the top level of a test file (parsed, not
    imported: the benchmarks do not import the test suite)."""
    tree = ast.parse((ROOT / path).read_text())
    return {node.name for node in tree.body
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test_")}


def pins_by_file(files):
    """{claim: (test file, test function)}, a study's PINS, from {test file: {claim: test
    function}}: the pins written file by file."""
    return {claim: (path, function)
            for path, claims in files.items() for claim, function in claims.items()}


def pinned_ids(pins):
    """pins: {claim: (test file relative to the repository, test function)} -> the template
    fields {"test": {claim: "file::function"}, "short": {claim: "::function"}}, after checking
    that every function is defined in its file (LookupError otherwise)."""
    test, short = {}, {}
    names = {}
    for claim, (path, function) in pins.items():
        if path not in names:
            names[path] = defined_tests(path)
        if function not in names[path]:
            raise LookupError(f"{path} defines no {function} (the test of claim {claim!r}): "
                              "renamed? update the study's PINS")
        test[claim] = f"{path}::{function}"
        short[claim] = f"::{function}"
    return {"test": test, "short": short}


def quoted_tests(text):
    """[(test file, function)] of every test id in a report: `file::function`, or `::function`
    standing for the file named last before it."""
    out, path = [], None
    for match in TEST_ID.finditer(text):
        path = match.group(1) or path
        out.append((path, match.group(2)))
    return out


def output_path(output, quick, default):
    """Where a study writes its report. `output` if given (relative to report.RESULTS, or
    absolute); else `default` in report.RESULTS, except a --quick run aimed at the committed
    benchmarks/results/, which goes to a new temporary directory instead (as `python -m
    benchmarks all --quick` does), so a quick run never replaces the full report or its charts."""
    if output is not None:
        return report.RESULTS / output
    committed = Path(report.__file__).resolve().parent / "results"
    if quick and Path(report.RESULTS).resolve() == committed:
        return Path(tempfile.mkdtemp(prefix="ptrace-benchmarks-")) / default
    return report.RESULTS / default


def study_arguments(argv, description, quick_help, default):
    """A study's command line: --quick (quick_help says what it shrinks), --threads (2; numba
    is set to it, at most to numba's maximum) and --output, which comes back as the report's
    path (`output_path`: `default` unless given)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--quick", action="store_true", help=quick_help)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--output", default=None,
                        help=f"report path (relative to benchmarks/results/; default {default}, "
                             "or a temporary directory with --quick); charts and "
                             f"{Path(default).stem}.json go beside it")
    args = parser.parse_args(argv)
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    args.output = output_path(args.output, args.quick, default)
    return args


def study_text(text, run, reproduce, notes, sections):
    """A study's whole report from its template's blocks `text`: the header (report.header of
    text["title"]), the intro (text["intro"] filled from run, reproduce, notes and the run's
    --quick flag), the sections (Markdown strings) and text["total"] filled from run."""
    intro = fill(text["intro"], run, reproduce=reproduce, notes=notes,
                 quick_flag=" --quick" if run["quick"] else "")
    return "\n".join([report.header(text["title"]), intro, "", "\n\n".join(sections), "",
                      fill(text["total"], run), ""])


def write_study(data, output, report_text):
    """Write the report report_text(data, chart folder) returns to output (relative to
    report.RESULTS, or absolute), the charts it saves beside it and data itself as JSON beside
    it (same name, .json); return the report's path."""
    path = report.destination(output)
    text = report_text(data, path.parent)
    save_json(path, data)
    return report.write(path, text)
