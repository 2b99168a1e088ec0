"""Checks shared by the tests of the study reports, studies.stability
(tests/test_benchmark_stability_geometry.py) and studies.stability_light
(tests/test_benchmark_stability_light.py), imported as `check`: a report written from data
(`written`), what it says (`says`), its tables (`tables`), the tests it quotes (`quoted_tests`)
and its charts (`charts`); a renamed pin (`renamed_pin_stops`); the quick run (`quick_run`);
the report written again from its JSON (`written_again`).
"""
import json
import re

import numba
import pytest

from benchmarks import report, templating


def cells(row):
    """The cells of a Markdown table row (an escaped pipe, \\|, is inside a cell)."""
    return re.split(r"(?<!\\)\|", row.strip().strip("|"))


def tables(text):
    """Every table row has as many cells as its header."""
    for table in re.findall(r"(?:^\|.*\|\n)+", text + "\n", re.M):
        lines = table.strip().splitlines()
        assert all(len(cells(line)) == len(cells(lines[0])) for line in lines), table


def quoted_tests(text):
    """The report names tests, each defined in its file; returns them, [(file, function)]."""
    quoted = templating.quoted_tests(text)
    assert quoted
    for path, function in quoted:
        assert function in templating.defined_tests(path), (path, function)
    return quoted


def says(text, *phrases):
    """Every phrase is in the report's text (the assertion lists those that are not)."""
    missing = [phrase for phrase in phrases if phrase not in text]
    assert not missing, f"not in the report: {missing}"


def charts(folder, names):
    """Each chart was saved into folder, and is not empty."""
    for name in names:
        assert (folder / name).stat().st_size > 1000, name


def written(write_report, data, name):
    """(path, text) of write_report(data, name), data being plain (JSON gives it back
    unchanged) and the JSON saved beside the report being data."""
    assert templating.plain(data) == json.loads(json.dumps(data)) == data
    path = write_report(data, name)
    text = path.read_text()
    assert json.loads(path.with_suffix(".json").read_text()) == data
    return path, text


def renamed_pin_stops(monkeypatch, pins, claim, write):
    """With the test of pins[claim] renamed, write() raises a LookupError that names it."""
    path, _ = pins[claim]
    monkeypatch.setitem(pins, claim, (path, "test_that_was_renamed"))
    with pytest.raises(LookupError, match="test_that_was_renamed"):
        write()


def quick_run(main, output):
    """The text of the report main(["--quick", "--output", output]) writes (main returns 0);
    numba's thread count is restored after it."""
    threads = numba.get_num_threads()
    try:
        assert main(["--quick", "--output", str(output)]) == 0
    finally:
        numba.set_num_threads(threads)
    return output.read_text()


def written_again(monkeypatch, write_report, path, skip=("- date",)):
    """The report at path is a function of the JSON beside it: written again from that JSON
    (into path's folder/again), the same text but for the lines that start with skip (the
    header's date). Returns the JSON's data."""
    data = json.loads(path.with_suffix(".json").read_text())
    monkeypatch.setattr(report, "RESULTS", path.parent / "again")
    again = write_report(data, path.name).read_text()

    def kept(text):
        return [line for line in text.splitlines() if not line.startswith(skip)]
    assert kept(again) == kept(path.read_text())
    return data
